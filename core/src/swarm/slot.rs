//! What the swarm keeps of one vehicle between ticks: whether it is flown here (its
//! link) or by another shard (what that shard last reported of it), and the estimates
//! and hold points its laws carry. The pure laws take their inputs as contiguous
//! slices (`LawArrays` in mod.rs), assembled from these once per tick.

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::geo::Geodetic;
use ringswarm_wire::time::SimTime;

use super::CommonState;
use super::model::FlownModel;
use crate::vehicle::{Phase, VehicleLink};

/// What is known of a vehicle another shard flies, from that shard's latest report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RemoteVehicle {
    pub(super) phase: Phase,
    pub(super) landed: bool,
    /// When its shard received the position (this shard's clock).
    pub(super) measured: SimTime,
    /// When its shard sent it (its control tick, this shard's clock).
    pub(super) sent: SimTime,
    pub(super) state: CommonState,
    /// Its unseen speed as its shard counts it (m/s, finite and ≥ 0).
    pub(super) unseen_mps: f64,
}

/// A vehicle flown here, or by another shard.
#[derive(Debug, Clone)]
// One per vehicle, as the links always were; a box would put a pointer hop on every
// tick's visit of every link, for the memory of the few remote ones.
#[allow(clippy::large_enum_variant)]
pub(super) enum Member {
    /// Flown by this process: its link.
    Local(VehicleLink),
    /// Flown by another shard: what it reported last (nothing before its first report).
    Remote(Option<RemoteVehicle>),
}

/// One vehicle's slot in the swarm.
#[derive(Debug, Clone)]
pub(super) struct VehicleSlot {
    /// Flown here or elsewhere.
    pub(super) member: Member,
    /// Its origin with its NED offset (m) from the common reference, projected once when
    /// the origin is learnt (not at every use: the projection costs trigonometry).
    pub(super) origin_offset: Option<(Geodetic, Vector3<f64>)>,
    /// Whether it has been inside the fence's altitude band (by its margin): from then on
    /// the band counts for it (a swarm climbing into the band from the ground is not
    /// stopped by it).
    pub(super) fence_band_reached: bool,
    /// A non-finite command isolated it (handed to its own Hold).
    pub(super) isolated: bool,
    /// The model flown for it: hover thrust, drag, disturbance and response estimates.
    pub(super) flown: FlownModel,
    /// Its altitude loop's integral.
    pub(super) altitude_integral: f64,
    /// Its vertical command (m/s², up).
    pub(super) u_z: f64,
    /// The velocity it holds while the swarm waits for the others (taken when it first
    /// flies on our commands), and the re-target stage's planned velocity (m/s, ENU).
    pub(super) keep_velocity: Option<Vector2<f64>>,
    /// Where it holds while holding (m, ENU); while it waits to land, the spot clear
    /// of the others it flies to first.
    pub(super) hold_point: Option<Vector2<f64>>,
    /// While it waits to land clear of a vehicle below it (`super::landing`): the
    /// altitude it holds meanwhile (m, up, common frame).
    pub(super) waits_to_land: Option<f64>,
    /// Where it holds, having taken off under the swarm, while the swarm waits for the
    /// others (the handshake; m, ENU).
    pub(super) keep_point: Option<Vector2<f64>>,
    /// Whether it was seen on the ground before it first flew.
    pub(super) started_on_ground: bool,
    /// The formation place it flies to (m, ENU, from the formation's centre): its offset
    /// `dᵢ` as configured, or the place assigned it at the start of consensus.
    pub(super) place_m: Vector2<f64>,
}

impl VehicleSlot {
    /// A vehicle as `member`, flown with `flown`, flying to `place_m`.
    pub(super) fn new(member: Member, flown: FlownModel, place_m: Vector2<f64>) -> Self {
        Self {
            member,
            origin_offset: None,
            fence_band_reached: false,
            isolated: false,
            flown,
            altitude_integral: 0.0,
            u_z: 0.0,
            keep_velocity: None,
            hold_point: None,
            waits_to_land: None,
            keep_point: None,
            started_on_ground: false,
            place_m,
        }
    }

    /// Its link, when flown here.
    pub(super) fn link(&self) -> Option<&VehicleLink> {
        match &self.member {
            Member::Local(link) => Some(link),
            Member::Remote(_) => None,
        }
    }

    /// Its link, when flown here.
    pub(super) fn link_mut(&mut self) -> Option<&mut VehicleLink> {
        match &mut self.member {
            Member::Local(link) => Some(link),
            Member::Remote(_) => None,
        }
    }

    /// What its shard last reported, when flown elsewhere.
    pub(super) fn remote(&self) -> Option<&RemoteVehicle> {
        match &self.member {
            Member::Remote(r) => r.as_ref(),
            Member::Local(_) => None,
        }
    }

    /// Its unseen speed (m/s): its link's count here, or what its own shard reported.
    pub(super) fn unseen_mps(&self) -> f64 {
        match &self.member {
            Member::Local(link) => link.unseen_speed_mps(),
            Member::Remote(r) => r.as_ref().map_or(0.0, |r| r.unseen_mps),
        }
    }

    /// Whether another shard flies it.
    pub(super) fn is_remote(&self) -> bool {
        matches!(self.member, Member::Remote(_))
    }

    /// Its link phase: its link's, or its shard's report of it (`discovering` until one
    /// comes).
    pub(super) fn phase(&self) -> Phase {
        match &self.member {
            Member::Local(link) => link.phase(),
            Member::Remote(r) => r.map_or(Phase::Discovering, |r| r.phase),
        }
    }
}
