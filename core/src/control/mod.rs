//! From the laws' accelerations to what a vehicle is sent: the altitude PID loop, the
//! in-flight hover thrust and drag estimates,
//! actuator envelope with its two saturation modes, and the conversion of an acceleration
//! into an attitude quaternion (NED→FRD) and normalised thrust. Pure and synchronous:
//! no I/O, no clock, no tokio or mavlink.

mod altitude;
mod attitude;
mod disturbance;
mod drag;
mod envelope;
mod frames;
mod hover;
mod response;
mod unseen;
mod vehicle;

pub use altitude::AltitudeGains;
pub use attitude::{
    AttitudeThrust, attitude_thrust_from_acceleration, thrust_direction_enu, tilt_cos,
};
pub use disturbance::{DISTURBANCE_LIMIT_MPS2, DisturbanceObserver};
pub use drag::DragKf;
pub use envelope::{Envelope, SaturationMode, SaturationSummary, saturate, saturate_with};
pub use frames::{enu_to_ned, euler_ned_frd, ned_to_enu, quaternion_to_wxyz, roll_pitch_ned_frd};
pub use hover::HoverThrustEkf;
pub use response::{AttitudeResponse, ResponseFit};
pub use unseen::UnseenMotion;
pub use vehicle::{GRAVITY_MPS2, VehicleModel};
