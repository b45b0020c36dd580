//! Which shard flies which vehicle, and which other vehicles' states a shard reads.

use std::time::Duration;

use crate::consensus::RingDigraph;

/// Which remote vehicles' states a shard reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Watch {
    /// Every remote vehicle (default): the swarm-wide checks (every vehicle flying, a
    /// vehicle lost, the divergence guard's formation) and the safety filter see the
    /// whole swarm, at `N · 37 B` per control tick into each shard.
    #[default]
    All,
    /// Only the ring in-neighbours of the shard's own vehicles, the law's inputs: the
    /// other shards are known by their reports alone. The safety filter then keeps the
    /// shard's vehicles apart from each other and from those neighbours only.
    Neighbours,
    /// The ring in-neighbours, as `Neighbours`, plus every remote vehicle in a tile
    /// within the safety filter's horizon of one of the shard's own vehicles
    /// ([`super::tiles`]): the swarm-wide checks go by the shards' reports, and the
    /// safety filter sees every vehicle close enough to matter.
    Horizon,
}

impl Watch {
    /// `all` or `neighbours`.
    pub fn name(self) -> &'static str {
        match self {
            Self::All => "all",
            Self::Neighbours => "neighbours",
            Self::Horizon => "horizon",
        }
    }
}

/// Why a plan cannot be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardPlanError {
    /// The owner table does not have one entry per vehicle of the ring.
    #[error("{got} vehicle owners for a ring of {expected} vehicles")]
    WrongLength {
        /// The ring's vehicles.
        expected: usize,
        /// The table's entries.
        got: usize,
    },
    /// A vehicle's owner is not a shard.
    #[error("vehicle {vehicle} is given to shard {shard}, but there are only {shards} shards")]
    NoSuchShard {
        /// The vehicle (0-based).
        vehicle: usize,
        /// Its owner.
        shard: usize,
        /// How many shards there are.
        shards: usize,
    },
    /// A shard flies no vehicle.
    #[error("shard {0} flies no vehicle")]
    Empty(usize),
    /// More than 65 535 vehicles or shards (the payload counts them in 16 bits).
    #[error("{0} is more than a payload counts (65 535)")]
    TooMany(usize),
}

/// One shard's view of the split.
#[derive(Debug, Clone, PartialEq)]
pub struct ShardPlan {
    this: usize,
    shards: usize,
    owner: Vec<usize>,
    watched: Vec<bool>,
    /// Whether another shard reads this vehicle's state (its own only).
    read_elsewhere: Vec<bool>,
    /// Whether this shard knows the state of the vehicle and of each of its ring
    /// in-neighbours: its law command can be computed here.
    computable: Vec<bool>,
    watch: Watch,
    start_lead: Duration,
    epoch_us: u64,
    tile_m: f64,
}

impl ShardPlan {
    /// Shard `this` of `shards`, vehicle `i` flown by shard `owner[i]`.
    ///
    /// # Errors
    /// [`ShardPlanError`] when the table does not fit the ring or the shards.
    pub fn new(
        this: usize,
        shards: usize,
        owner: Vec<usize>,
        ring: &RingDigraph,
        watch: Watch,
    ) -> Result<Self, ShardPlanError> {
        let n = ring.agents();
        if owner.len() != n {
            return Err(ShardPlanError::WrongLength {
                expected: n,
                got: owner.len(),
            });
        }
        for big in [n, shards] {
            if big > usize::from(u16::MAX) {
                return Err(ShardPlanError::TooMany(big));
            }
        }
        if this >= shards {
            return Err(ShardPlanError::NoSuchShard {
                vehicle: 0,
                shard: this,
                shards,
            });
        }
        if let Some((vehicle, &shard)) = owner.iter().enumerate().find(|(_, s)| **s >= shards) {
            return Err(ShardPlanError::NoSuchShard {
                vehicle,
                shard,
                shards,
            });
        }
        if let Some(empty) = (0..shards).find(|s| !owner.contains(s)) {
            return Err(ShardPlanError::Empty(empty));
        }
        // Vehicle j is read by the shards flying its out-neighbours (the law), or by
        // every other shard (watch all).
        let mut read_by: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, reader) in owner.iter().enumerate() {
            for e in ring.neighbours(i).iter() {
                read_by[e.from].push(*reader);
            }
        }
        let watched: Vec<bool> = (0..n)
            .map(|j| {
                owner[j] != this
                    && match watch {
                        Watch::All => true,
                        Watch::Neighbours | Watch::Horizon => read_by[j].contains(&this),
                    }
            })
            .collect();
        let read_elsewhere = (0..n)
            .map(|j| {
                owner[j] == this
                    && match watch {
                        // Any shard may have a vehicle near it.
                        Watch::All | Watch::Horizon => shards > 1,
                        Watch::Neighbours => read_by[j].iter().any(|s| *s != this),
                    }
            })
            .collect();
        let known = |j: usize| owner[j] == this || watched[j];
        let computable = (0..n)
            .map(|i| known(i) && ring.neighbours(i).iter().all(|e| known(e.from)))
            .collect();
        Ok(Self {
            this,
            shards,
            owner,
            watched,
            read_elsewhere,
            computable,
            watch,
            start_lead: DEFAULT_START_LEAD,
            epoch_us: 0,
            tile_m: DEFAULT_TILE_M,
        })
    }

    /// With consensus proposed `lead` after a shard sees every vehicle flying.
    pub fn with_start_lead(mut self, lead: Duration) -> Self {
        self.start_lead = lead;
        self
    }

    /// With the swarm clock at `epoch_us` (µs) when this shard's own clock reads zero.
    pub fn with_epoch_us(mut self, epoch_us: u64) -> Self {
        self.epoch_us = epoch_us;
        self
    }

    /// With states published in tiles of `tile_m` (m; finite and positive, the config
    /// checks it). Every shard of a swarm uses the same.
    pub fn with_tile_m(mut self, tile_m: f64) -> Self {
        self.tile_m = tile_m;
        self
    }

    /// The tiles' side (m).
    pub fn tile_m(&self) -> f64 {
        self.tile_m
    }

    /// This shard's index.
    pub fn this(&self) -> usize {
        self.this
    }

    /// How many shards there are.
    pub fn shards(&self) -> usize {
        self.shards
    }

    /// The shard flying vehicle `i`.
    pub fn owner(&self, i: usize) -> Option<usize> {
        self.owner.get(i).copied()
    }

    /// Whether this shard flies vehicle `i`.
    pub fn is_local(&self, i: usize) -> bool {
        self.owner(i) == Some(self.this)
    }

    /// Whether this shard reads remote vehicle `i`'s state.
    pub fn is_watched(&self, i: usize) -> bool {
        self.watched.get(i).copied().unwrap_or(false)
    }

    /// Whether vehicle `i`'s law command can be computed here (its state and its ring
    /// in-neighbours' are known): the saturation's `conserve` counts it.
    pub fn is_computable(&self, i: usize) -> bool {
        self.computable.get(i).copied().unwrap_or(false)
    }

    /// Whether another shard reads this shard's vehicle `i`: its state is published.
    pub fn is_read_elsewhere(&self, i: usize) -> bool {
        self.read_elsewhere.get(i).copied().unwrap_or(false)
    }

    /// How many vehicles the swarm has.
    pub fn vehicle_count(&self) -> usize {
        self.owner.len()
    }

    /// How many vehicles shard `s` flies.
    pub fn vehicles_of(&self, s: usize) -> usize {
        self.owner.iter().filter(|o| **o == s).count()
    }

    /// What is watched.
    pub fn watch(&self) -> Watch {
        self.watch
    }

    /// How long after a shard sees every vehicle flying it proposes to start consensus.
    pub fn start_lead(&self) -> Duration {
        self.start_lead
    }

    /// The swarm clock (µs) at this shard's zero.
    pub fn epoch_us(&self) -> u64 {
        self.epoch_us
    }
}

/// The default [`ShardPlan::tile_m`] (m): a horizon of 60–130 m (vehicles at 5–15 m/s)
/// then needs 4–9 tiles about one vehicle.
pub const DEFAULT_TILE_M: f64 = 100.0;

/// The default [`ShardPlan::start_lead`]: ten control periods at 50 Hz, ten times a
/// 20 ms hop between shards.
pub const DEFAULT_START_LEAD: Duration = Duration::from_millis(200);

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(n: usize) -> RingDigraph {
        RingDigraph::for_agents(n, 3.0).unwrap()
    }

    #[test]
    fn three_shards_of_two_read_only_the_previous_macro_vertex_with_neighbours() {
        // Vehicle 2i reads 2i+1 and 2i−1; vehicle 2i+1 reads 2i. Shard s flies 2s, 2s+1,
        // so it reads vehicle 2s−1 only, and vehicle 2s+1 is read by the next shard.
        let owner = vec![0, 0, 1, 1, 2, 2];
        let plan = ShardPlan::new(1, 3, owner.clone(), &ring(6), Watch::Neighbours).unwrap();
        let watched: Vec<usize> = (0..6).filter(|i| plan.is_watched(*i)).collect();
        assert_eq!(watched, vec![1]);
        let published: Vec<usize> = (0..6).filter(|i| plan.is_read_elsewhere(*i)).collect();
        assert_eq!(published, vec![3]);
        assert_eq!(plan.vehicles_of(2), 2);
        let computable: Vec<usize> = (0..6).filter(|i| plan.is_computable(*i)).collect();
        assert_eq!(computable, vec![2, 3]);
        let all = ShardPlan::new(1, 3, owner, &ring(6), Watch::All).unwrap();
        assert!((0..6).all(|i| all.is_computable(i)));
        let watched: Vec<usize> = (0..6).filter(|i| all.is_watched(*i)).collect();
        assert_eq!(watched, vec![0, 1, 4, 5]);
        assert!(all.is_read_elsewhere(2) && all.is_read_elsewhere(3));
        // The horizon reads the neighbours, as `Neighbours`, and publishes every vehicle.
        let horizon =
            ShardPlan::new(1, 3, vec![0, 0, 1, 1, 2, 2], &ring(6), Watch::Horizon).unwrap();
        let watched: Vec<usize> = (0..6).filter(|i| horizon.is_watched(*i)).collect();
        assert_eq!(watched, vec![1]);
        let published: Vec<usize> = (0..6).filter(|i| horizon.is_read_elsewhere(*i)).collect();
        assert_eq!(published, vec![2, 3]);
        assert_eq!(horizon.tile_m(), DEFAULT_TILE_M);
    }

    #[test]
    fn a_macro_vertex_split_over_two_shards_reads_both_ways() {
        // Shard 0 flies 0 and 2, shard 1 flies 1 and 3: 1 reads 0, 0 reads 1 and 3,
        // 2 reads 3 and 1, 3 reads 2.
        let plan = ShardPlan::new(0, 2, vec![0, 1, 0, 1], &ring(4), Watch::Neighbours).unwrap();
        assert!(plan.is_watched(1) && plan.is_watched(3));
        assert!(plan.is_read_elsewhere(0) && plan.is_read_elsewhere(2));
    }

    #[test]
    fn bad_tables_are_named() {
        let r = ring(4);
        assert_eq!(
            ShardPlan::new(0, 2, vec![0, 0, 1], &r, Watch::All),
            Err(ShardPlanError::WrongLength {
                expected: 4,
                got: 3
            })
        );
        assert_eq!(
            ShardPlan::new(0, 2, vec![0, 0, 2, 1], &r, Watch::All),
            Err(ShardPlanError::NoSuchShard {
                vehicle: 2,
                shard: 2,
                shards: 2
            })
        );
        assert_eq!(
            ShardPlan::new(0, 3, vec![0, 0, 1, 1], &r, Watch::All),
            Err(ShardPlanError::Empty(2))
        );
        assert_eq!(
            ShardPlan::new(0, 2, vec![0, 0, 1, 2], &r, Watch::All)
                .unwrap_err()
                .to_string(),
            "vehicle 3 is given to shard 2, but there are only 2 shards"
        );
    }
}
