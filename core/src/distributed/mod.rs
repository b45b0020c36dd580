//! The swarm split into shards: each shard flies its own vehicles over MAVLink and
//! shares with the others, every control tick, what their vehicles' laws and the
//! swarm-wide decisions need (docs/distributed.md).
//!
//! - [`plan`]: which shard flies which vehicle, and which remote states a shard reads.
//! - [`payload`]: the messages between shards and their versioned bytes.
//! - [`tiles`]: where a state is published, and which a shard reads for its safety filter.
//!
//! The swarm machine takes these messages and makes them
//! ([`crate::swarm::Swarm::handle_shard_message`], [`crate::swarm::Swarm::poll_shard_message`]);
//! a driver carries them (in lockstep, or over Zenoh).

pub mod payload;
pub mod plan;
pub mod tiles;

pub use payload::{
    MemberPhase, PAYLOAD_VERSION, PayloadError, PlanVelocities, ShardMessage, ShardReport,
    StartPositions, VehicleReport, WeightedSum, decode, encode, encode_into_batch, split_batch,
};
pub use plan::{DEFAULT_START_LEAD, DEFAULT_TILE_M, ShardPlan, ShardPlanError, Watch};
pub use tiles::{Tile, TileInterest};
