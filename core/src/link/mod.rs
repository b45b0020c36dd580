//! The MAVLink edge of the coordinator: framing (`ringswarm-wire`'s codec, shared with
//! the emulator but not taken from it) and conversions between MAVLink messages and
//! domain types.
//! MAVLink identifiers appear only here and in the emulator.

mod convert;
pub mod provision;
pub mod router;

pub use convert::{
    AUTOPILOT_PX4, Inbound, autopilot_name, fence_count, fence_item, gcs_heartbeat, inbound,
    mission_result_name, set_attitude_target, set_position_target_acceleration, timesync_request,
};
pub use ringswarm_wire::codec::{
    Encoder, Frame, FrameError, decode_datagram, decode_datagram_with, frame_system_id, frames,
    raw_frames,
};
