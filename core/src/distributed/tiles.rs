//! Square tiles of the common frame's horizontal plane: where a vehicle's state is
//! published, and which states a shard reads for its safety filter ([`Watch::Horizon`]).
//!
//! A vehicle's state is published under a key ending in the tile its position is in
//! ([`Tile::chunk`]). A shard reads every tile within its horizon of one of its own
//! vehicles: the distance at which the safety filter starts to look at a pair, plus what
//! the vehicles can close while a new subscription takes effect. A vehicle of another
//! shard inside that distance lies in a tile that meets the square of that half-side
//! about one of this shard's vehicles, so it is read.
//!
//! [`Watch::Horizon`]: super::Watch::Horizon

use std::collections::BTreeSet;

use nalgebra::Vector2;

/// More tiles than this and a shard reads every state instead (`state/**`): a horizon
/// that large (fast vehicles, small tiles) would declare more subscriptions than it
/// saves.
pub const MAX_TILES: usize = 1024;

/// The time a new tile's subscription is given to take effect, counted in the horizon
/// on top of the safety filter's look-ahead (s): the next control tick computes it, the
/// transport declares it, and the first state under it crosses one hop.
pub const SUBSCRIPTION_LAG_S: f64 = 1.0;

/// One tile: `[east·size, (east+1)·size) × [north·size, (north+1)·size)` (m, ENU about
/// the common reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Tile {
    /// Index along east.
    pub east: i32,
    /// Index along north.
    pub north: i32,
}

impl Tile {
    /// The tile holding `pos_m` (x east, y north), for tiles of `size_m`; `None` for a
    /// non-finite position or one beyond the indices' range.
    pub fn of(pos_m: Vector2<f64>, size_m: f64) -> Option<Self> {
        let index = |x: f64| {
            let i = (x / size_m).floor();
            (i.is_finite() && i >= f64::from(i32::MIN) && i <= f64::from(i32::MAX))
                .then_some(i as i32)
        };
        Some(Self {
            east: index(pos_m.x)?,
            north: index(pos_m.y)?,
        })
    }

    /// Its key chunk: `e<east>n<north>`, e.g. `e-3n12`.
    pub fn chunk(&self) -> String {
        format!("e{}n{}", self.east, self.north)
    }
}

/// The tiles a shard reads.
#[derive(Debug, Clone, PartialEq)]
pub struct TileInterest {
    size_m: f64,
    tiles: BTreeSet<Tile>,
    everything: bool,
    generation: u64,
    scratch: BTreeSet<Tile>,
}

impl TileInterest {
    /// No tile yet, for tiles of `size_m` (m, finite and positive: the config checks it).
    pub fn new(size_m: f64) -> Self {
        Self {
            size_m,
            tiles: BTreeSet::new(),
            everything: false,
            generation: 0,
            scratch: BTreeSet::new(),
        }
    }

    /// The tiles' side (m).
    pub fn size_m(&self) -> f64 {
        self.size_m
    }

    /// Re-reckons the tiles from this shard's own vehicles' positions (m, ENU) and the
    /// horizon `radius_m`: every tile meeting the square of half-side `radius_m` about one
    /// of them. A tile already read is kept while it meets the square half a tile wider,
    /// so that a vehicle on a border does not make the subscription come and go. A
    /// non-finite radius reads everything. Whether anything changed.
    pub fn update(
        &mut self,
        positions: impl IntoIterator<Item = Vector2<f64>>,
        radius_m: f64,
    ) -> bool {
        let positions: Vec<Vector2<f64>> = positions
            .into_iter()
            .filter(|p| p.iter().all(|x| x.is_finite()))
            .collect();
        let everything = !radius_m.is_finite()
            || !self.add_squares(&positions, radius_m.max(0.0))
            || self.scratch.len() > MAX_TILES;
        let wanted = std::mem::take(&mut self.scratch);
        let next = if everything {
            BTreeSet::new()
        } else if self.everything {
            wanted
        } else {
            // Keep what the wider squares still meet.
            let wider = radius_m.max(0.0) + 0.5 * self.size_m;
            let keep: Vec<Tile> = self
                .tiles
                .iter()
                .copied()
                .filter(|t| !wanted.contains(t))
                .filter(|t| positions.iter().any(|p| self.meets(*t, *p, wider)))
                .collect();
            let mut next = wanted;
            next.extend(keep);
            next
        };
        let next_everything = everything || next.len() > MAX_TILES;
        let changed =
            next_everything != self.everything || (!next_everything && next != self.tiles);
        self.everything = next_everything;
        self.tiles = if next_everything {
            BTreeSet::new()
        } else {
            next
        };
        if changed {
            self.generation += 1;
        }
        changed
    }

    /// Puts every tile meeting one of the squares into the scratch set; false when the
    /// squares hold more than [`MAX_TILES`] tiles (they are then not all in).
    fn add_squares(&mut self, positions: &[Vector2<f64>], radius_m: f64) -> bool {
        self.scratch.clear();
        let r = Vector2::new(radius_m, radius_m);
        for p in positions {
            let (Some(low), Some(high)) =
                (Tile::of(p - r, self.size_m), Tile::of(p + r, self.size_m))
            else {
                return false;
            };
            let span = |a: i32, b: i32| (i64::from(b) - i64::from(a) + 1).max(0);
            if span(low.east, high.east) * span(low.north, high.north) > MAX_TILES as i64 {
                return false;
            }
            for east in low.east..=high.east {
                for north in low.north..=high.north {
                    self.scratch.insert(Tile { east, north });
                }
            }
            if self.scratch.len() > MAX_TILES {
                return false;
            }
        }
        true
    }

    /// Whether tile `t` meets the square of half-side `half_m` about `p`.
    fn meets(&self, t: Tile, p: Vector2<f64>, half_m: f64) -> bool {
        let s = self.size_m;
        let (e0, n0) = (f64::from(t.east) * s, f64::from(t.north) * s);
        p.x + half_m >= e0 && p.x - half_m < e0 + s && p.y + half_m >= n0 && p.y - half_m < n0 + s
    }

    /// Whether every state is read (the horizon holds more than [`MAX_TILES`] tiles).
    pub fn everything(&self) -> bool {
        self.everything
    }

    /// Whether a state at `pos_m` is read.
    pub fn reads(&self, pos_m: Vector2<f64>) -> bool {
        self.everything || Tile::of(pos_m, self.size_m).is_some_and(|t| self.tiles.contains(&t))
    }

    /// The tiles read (none when [`Self::everything`]), in order.
    pub fn tiles(&self) -> impl Iterator<Item = Tile> + '_ {
        self.tiles.iter().copied()
    }

    /// How many tiles are read.
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    /// Whether no tile is read (and not everything).
    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty() && !self.everything
    }

    /// Bumped on every change: a transport re-declares its subscriptions when it moves.
    pub fn generation(&self) -> u64 {
        self.generation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_position_falls_in_the_tile_below_and_left_of_it() {
        let t = |x: f64, y: f64| Tile::of(Vector2::new(x, y), 100.0).unwrap();
        assert_eq!(t(0.0, 0.0), Tile { east: 0, north: 0 });
        assert_eq!(t(99.9, 100.0), Tile { east: 0, north: 1 });
        assert_eq!(
            t(-0.1, -250.0),
            Tile {
                east: -1,
                north: -3
            }
        );
        assert_eq!(t(-0.1, -250.0).chunk(), "e-1n-3");
        assert_eq!(Tile::of(Vector2::new(f64::NAN, 0.0), 100.0), None);
        assert_eq!(Tile::of(Vector2::new(1e300, 0.0), 100.0), None);
    }

    #[test]
    fn the_tiles_cover_the_horizon_square_and_nothing_more() {
        let mut interest = TileInterest::new(100.0);
        // A vehicle at (150, 50) with a 60 m horizon: east 90..210 meets tiles 0..=2,
        // north −10..110 meets tiles −1..=1.
        assert!(interest.update([Vector2::new(150.0, 50.0)], 60.0));
        let tiles: Vec<(i32, i32)> = interest.tiles().map(|t| (t.east, t.north)).collect();
        let mut expected = Vec::new();
        for e in 0..=2 {
            for n in -1..=1 {
                expected.push((e, n));
            }
        }
        assert_eq!(tiles, expected);
        assert_eq!(interest.generation(), 1);
        // Every point within the horizon is read; a point just outside the square is not.
        for (dx, dy) in [(59.0, 59.0), (-59.0, -59.0), (0.0, 59.9), (-59.9, 0.0)] {
            assert!(interest.reads(Vector2::new(150.0 + dx, 50.0 + dy)));
        }
        assert!(!interest.reads(Vector2::new(310.0, 50.0)));
        assert!(!interest.update([Vector2::new(150.0, 50.0)], 60.0));
        assert_eq!(interest.generation(), 1);
    }

    #[test]
    fn a_vehicle_on_a_border_does_not_make_the_tiles_flap() {
        let mut interest = TileInterest::new(100.0);
        // Horizon reaches x = 100 from 40 m: tile 1 along east is needed.
        interest.update([Vector2::new(41.0, 50.0)], 60.0);
        assert!(interest.reads(Vector2::new(101.0, 50.0)));
        let generation = interest.generation();
        // Back by 2 m: tile 1 is no longer needed, but it is within half a tile more.
        assert!(!interest.update([Vector2::new(39.0, 50.0)], 60.0));
        assert!(interest.reads(Vector2::new(101.0, 50.0)));
        // Back by 60 m: now it goes.
        assert!(interest.update([Vector2::new(-21.0, 50.0)], 60.0));
        assert!(!interest.reads(Vector2::new(101.0, 50.0)));
        assert_eq!(interest.generation(), generation + 1);
    }

    #[test]
    fn a_horizon_of_too_many_tiles_reads_everything_and_comes_back() {
        let mut interest = TileInterest::new(10.0);
        // 2 km square of 10 m tiles: 40 000 tiles.
        assert!(interest.update([Vector2::new(0.0, 0.0)], 1000.0));
        assert!(interest.everything() && interest.tiles().next().is_none());
        assert!(interest.reads(Vector2::new(5000.0, -5000.0)));
        assert!(interest.update([Vector2::new(0.0, 0.0)], 5.0));
        assert!(!interest.everything());
        assert_eq!(interest.len(), 4);
        // A non-finite horizon reads everything (never too little).
        assert!(interest.update([Vector2::new(0.0, 0.0)], f64::NAN));
        assert!(interest.everything());
    }

    #[test]
    fn no_position_reads_no_tile() {
        let mut interest = TileInterest::new(100.0);
        assert!(!interest.update([Vector2::new(f64::NAN, 0.0)], 60.0));
        assert!(interest.is_empty());
        assert!(!interest.reads(Vector2::new(0.0, 0.0)));
    }
}
