//! The two numbers a vehicle goes by, each its own type so that one is never taken for
//! the other (or for a shard or a socket number):
//! - [`VehicleIndex`]: its place in the swarm, the one index every per-vehicle array of
//!   the swarm machine and the router is kept in (ring order, the `[[vehicle]]` order);
//! - [`SystemId`]: its MAVLink system id, what its frames carry and what a network socket
//!   tells vehicles apart by (unique within a network, not across networks).

use std::fmt;
use std::ops::{Index, IndexMut};

/// A vehicle's index in ring order (0-based; the `[[vehicle]]` order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct VehicleIndex(pub usize);

impl VehicleIndex {
    /// The index as a number.
    pub fn get(self) -> usize {
        self.0
    }

    /// Every index of a swarm of `n` vehicles, in ring order.
    pub fn all(n: usize) -> impl DoubleEndedIterator<Item = Self> + ExactSizeIterator + Clone {
        (0..n).map(Self)
    }
}

impl fmt::Display for VehicleIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

impl From<usize> for VehicleIndex {
    fn from(i: usize) -> Self {
        Self(i)
    }
}

/// A vehicle's MAVLink system id (1–255; 0 is the broadcast and never a vehicle's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SystemId(pub u8);

impl SystemId {
    /// The id as carried in a frame's header.
    pub fn get(self) -> u8 {
        self.0
    }
}

impl fmt::Display for SystemId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// Every per-vehicle array is indexed by it.
impl<T> Index<VehicleIndex> for Vec<T> {
    type Output = T;

    fn index(&self, i: VehicleIndex) -> &T {
        &self[i.0]
    }
}

impl<T> IndexMut<VehicleIndex> for Vec<T> {
    fn index_mut(&mut self, i: VehicleIndex) -> &mut T {
        &mut self[i.0]
    }
}

impl<T> Index<VehicleIndex> for [T] {
    type Output = T;

    fn index(&self, i: VehicleIndex) -> &T {
        &self[i.0]
    }
}

impl<T> IndexMut<VehicleIndex> for [T] {
    fn index_mut(&mut self, i: VehicleIndex) -> &mut T {
        &mut self[i.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_index_reads_the_same_element_as_its_number() {
        let v: Vec<i32> = (1..=3).map(|k| 10 * k).collect();
        assert_eq!(v[VehicleIndex(2)], v[2]);
        assert_eq!(
            VehicleIndex::all(3).collect::<Vec<_>>(),
            [VehicleIndex(0), VehicleIndex(1), VehicleIndex(2)]
        );
        assert_eq!(VehicleIndex(7).to_string(), "7");
    }
}
