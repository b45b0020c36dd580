//! The MAVLink edge of the coordinator: framing (the emulator crate's codec, which has no
//! dependency on ringswarm) and conversions between MAVLink messages and domain types.
//! MAVLink identifiers appear only here and in the emulator.

mod convert;

pub use convert::{
    AUTOPILOT_PX4, Inbound, autopilot_name, gcs_heartbeat, inbound, set_attitude_target,
    set_position_target_acceleration,
};
pub use ringswarm_sitl::codec::{Encoder, Frame, FrameError, decode_datagram, raw_frames};
