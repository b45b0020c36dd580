//! The auction algorithm for the dense linear assignment problem (Bertsekas 1988; with
//! ε-scaling, Bertsekas & Eckstein), in its minimising form.
//!
//! Each unassigned person `i` bids for the object `j` of least `cᵢⱼ + pⱼ`, raising its
//! price `pⱼ` by the gap to its second-best object plus `ε`, and takes it from its owner.
//! When every person is assigned, each holds an object within `ε` of its best
//! (ε-complementary slackness), and the assignment costs at most `n·ε` more than the
//! optimum. On integer costs multiplied by `n + 1`, a final `ε = 1` is therefore
//! optimal. ε starts at a fraction of the largest cost and shrinks by [`SCALE`] per phase,
//! the prices carried from phase to phase: few bids per phase on the geometric costs of a
//! formation. Deterministic: the unassigned wait in a queue in index order.
//!
//! The costs are rounded to integers of 1/[`RESOLUTION`] of the largest cost (about 6e-8),
//! and the answer is optimal for the rounded costs.

use std::collections::VecDeque;

/// The largest rounded cost: costs are taken in units of the largest cost / `RESOLUTION`.
pub const RESOLUTION: f64 = (1u64 << 24) as f64;

/// How much ε shrinks from one phase to the next.
pub const SCALE: i64 = 8;

/// Most bids over all phases before giving up (far above what any formation needs:
/// a guard against a mistake, not a limit met in use).
const MAX_BIDS: u64 = 4_000_000_000;

/// The assignment of least total cost of the `n × n` costs (row-major, person by
/// object): `place[i]` is the object of person `i`.
///
/// # Errors
/// A cost that is negative or not finite, or more bids than [`MAX_BIDS`].
pub fn minimum_cost(n: usize, costs: &[f64]) -> Result<Vec<usize>, &'static str> {
    if costs.len() != n * n {
        return Err("the cost matrix is not n × n");
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    if costs.iter().any(|c| !c.is_finite() || *c < 0.0) {
        return Err("a cost is negative or not finite");
    }
    let largest = costs.iter().fold(0.0f64, |m, c| m.max(*c));
    let unit = if largest > 0.0 {
        largest / RESOLUTION
    } else {
        1.0
    };
    // Integer costs times (n + 1): a final ε of 1 is then below 1/n of a cost unit.
    let factor = i64::try_from(n + 1).map_err(|_| "too many vehicles")?;
    let c: Vec<i64> = costs
        .iter()
        .map(|x| (x / unit).round() as i64 * factor)
        .collect();
    let top = c.iter().copied().max().unwrap_or(0);
    let mut prices = vec![0i64; n];
    let mut owner: Vec<Option<usize>> = vec![None; n];
    let mut place: Vec<Option<usize>> = vec![None; n];
    let mut queue: VecDeque<usize> = VecDeque::with_capacity(n);
    let mut bids = 0u64;
    let mut eps = (top / 4).max(1);
    loop {
        owner.iter_mut().for_each(|o| *o = None);
        place.iter_mut().for_each(|p| *p = None);
        queue.clear();
        queue.extend(0..n);
        while let Some(i) = queue.pop_front() {
            bids += 1;
            if bids > MAX_BIDS {
                return Err("the auction did not end");
            }
            let row = &c[i * n..(i + 1) * n];
            // The best and second-best reduced costs, and the best object.
            let (mut best, mut second, mut j_best) = (i64::MAX, i64::MAX, 0);
            for (j, (&cost, &price)) in row.iter().zip(&prices).enumerate() {
                let v = cost + price;
                if v < best {
                    second = best;
                    best = v;
                    j_best = j;
                } else if v < second {
                    second = v;
                }
            }
            // A lone object (n = 1) is taken at ε.
            let raise = if second == i64::MAX {
                eps
            } else {
                second - best + eps
            };
            prices[j_best] += raise;
            if let Some(previous) = owner[j_best].replace(i) {
                place[previous] = None;
                queue.push_back(previous);
            }
            place[i] = Some(j_best);
        }
        if eps == 1 {
            break;
        }
        eps = (eps / SCALE).max(1);
    }
    place
        .into_iter()
        .map(|p| p.ok_or("a person was left unassigned"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_three_by_three_is_solved() {
        // Rows: [4 1 3], [2 0 5], [3 2 2]: the least total is 1 + 2 + 2 = 5
        // (person 0 → 1, 1 → 0, 2 → 2).
        let costs = [4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0];
        assert_eq!(minimum_cost(3, &costs).unwrap(), vec![1, 0, 2]);
    }

    #[test]
    fn ties_and_zeros_end() {
        assert_eq!(minimum_cost(1, &[0.0]).unwrap(), vec![0]);
        let zeros = vec![0.0; 64 * 64];
        let place = minimum_cost(64, &zeros).unwrap();
        let mut seen = place.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..64).collect::<Vec<_>>());
    }

    #[test]
    fn bad_costs_are_named() {
        assert_eq!(
            minimum_cost(2, &[0.0; 3]),
            Err("the cost matrix is not n × n")
        );
        assert_eq!(
            minimum_cost(1, &[f64::NAN]),
            Err("a cost is negative or not finite")
        );
        assert_eq!(
            minimum_cost(1, &[-1.0]),
            Err("a cost is negative or not finite")
        );
    }
}
