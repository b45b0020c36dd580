//! The MAVLink edge of the coordinator: framing (`ringswarm-wire`'s codec, shared with
//! the emulator but not taken from it) and conversions between MAVLink messages and
//! domain types.
//! MAVLink identifiers appear only here and in the emulator.

mod command;
mod convert;
mod dialect;
pub mod provision;
pub mod router;
mod signer;

pub use command::{VehicleCommand, command_long, command_name, mission_result_name, result_name};
pub use convert::{
    AUTOPILOT_PX4, Inbound, Outgoing, autopilot_name, encode, fence_count, fence_item,
    gcs_heartbeat, inbound, param_request_read, param_set, set_attitude_target,
    set_position_target_acceleration, timesync_request,
};
pub use dialect::{Autopilot, AutopilotChoice, ParamAction, ParamStep, StreamRate};
pub use ringswarm_wire::codec::{
    Encoder, Frame, FrameError, decode_datagram, decode_datagram_with, for_each_frame,
    frame_system_id, raw_frames,
};
pub use signer::{LinkSigning, Signer};
