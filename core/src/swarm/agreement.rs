//! The shards' agreement on one instant (sans-IO and pure: time and the other shards'
//! reports are arguments): when consensus starts, or, with a `[target]`, when every shard
//! takes the velocities the plan is made from. One process starts at once and has none.
//!
//! ```text
//!            every vehicle flying (this shard's view)
//!  Idle ───────────────────────────────────────────► Proposed: own = now + start_lead
//!   ▲                                                 adopted = earliest of own and the
//!   │ new_round (a hold began, a plan was made)        others' proposals of this round
//!   │                                                 (of this stage, after any void)
//!   │       a vehicle not flying: withdraw (vouch for nothing; the proposal stays)
//!   │
//!   │   now ≥ adopted, every other shard vouches for it ──► start: Started(adopted, sum)
//!   │   now ≥ adopted, one does not ──► void every proposal up to now, propose anew
//!   └── Started ── the prediction once every shard's sum at the instant is in
//! ```
//!
//! A shard vouches for an instant (its report's `start_us`) while it sees every vehicle
//! flying, and starts only once every other shard vouches for the same one: a shard
//! that cannot hear a third one (a broken mesh), or sees a vehicle down, holds every
//! shard back, so no shard flies consensus while another does not.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

use crate::distributed::{ShardReport, WeightedSum};

/// How long after the start a shard's report must show that it started too: a few
/// control ticks of any rate the config allows.
pub(super) const AGREEMENT_SETTLED: Duration = Duration::from_millis(100);

/// This shard's time and the swarm clock (µs since the Unix epoch on a real deployment).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct SwarmClock {
    /// The swarm clock at this shard's zero (µs).
    pub(super) epoch_us: u64,
}

impl SwarmClock {
    /// `t` on the swarm clock (µs).
    pub(super) fn to_swarm_us(self, t: SimTime) -> u64 {
        self.epoch_us.saturating_add(t.as_micros())
    }

    /// A swarm clock reading (µs) in this shard's time.
    pub(super) fn local_time_of(self, us: u64) -> SimTime {
        SimTime::from_micros(us.saturating_sub(self.epoch_us))
    }
}

/// What the agreement reads of the other shards: each one's latest report and when it
/// came (this shard's own slot empty), on the swarm clock.
#[derive(Debug, Clone, Copy)]
pub(super) struct Heard<'a> {
    /// Indexed by shard.
    pub(super) reports: &'a [Option<(SimTime, ShardReport)>],
    pub(super) clock: SwarmClock,
}

/// One shard's side of the agreement.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct StartAgreement {
    /// This shard's index.
    this: usize,
    /// How far ahead of the tick that proposes it a start is proposed.
    lead: Duration,
    /// This shard's proposal in the current round.
    proposal: Option<SimTime>,
    /// The instant this shard adopts and vouches for (it sees every vehicle flying).
    agreed: Option<SimTime>,
    /// When the current round started: proposals before it belong to an earlier one.
    round_since: SimTime,
    /// An instant that came without every shard's word is void, and so is every
    /// proposal up to it.
    void_until: Option<SimTime>,
    /// The instant adopted in the current round, and this shard's sum at it.
    started: Option<(SimTime, WeightedSum)>,
    /// Whether the prediction of the current round was made.
    predicted: bool,
    /// With a `[target]`: whether this shard has made the flight's plan. The instants of
    /// shards that have (consensus starts) and have not (plan instants) are never taken
    /// for each other.
    planned: bool,
}

impl StartAgreement {
    /// Shard `this`, proposing instants `lead` ahead.
    pub(super) fn new(this: usize, lead: Duration) -> Self {
        Self {
            this,
            lead,
            proposal: None,
            agreed: None,
            round_since: SimTime::ZERO,
            void_until: None,
            started: None,
            predicted: false,
            planned: false,
        }
    }

    /// A new round (a hold began, or the plan was made): earlier proposals are forgotten.
    pub(super) fn new_round(&mut self, now: SimTime) {
        self.round_since = now;
        self.proposal = None;
        self.agreed = None;
        self.void_until = None;
        self.started = None;
        self.predicted = false;
    }

    /// The plan is made: from now on this shard agrees on consensus starts.
    pub(super) fn set_planned(&mut self) {
        self.planned = true;
    }

    /// Whether this shard has made the flight's plan.
    pub(super) fn planned(&self) -> bool {
        self.planned
    }

    /// Whether this shard has proposed an instant in the current round.
    pub(super) fn proposed(&self) -> bool {
        self.proposal.is_some()
    }

    /// The instant adopted in this round and this shard's sum at it, once started.
    pub(super) fn started(&self) -> Option<(SimTime, WeightedSum)> {
        self.started
    }

    /// The instant this shard's report vouches for: the one it started at, or the one
    /// it adopts.
    pub(super) fn vouched(&self) -> Option<SimTime> {
        self.started.map(|(t, _)| t).or(self.agreed)
    }

    /// The earliest instant proposed in this round (of this stage, after any void),
    /// this shard's own included.
    pub(super) fn adopted(&self, heard: Heard<'_>) -> Option<SimTime> {
        let others = heard.reports.iter().flatten().filter_map(|(_, r)| {
            (r.planned == self.planned).then_some(())?;
            r.start_us
                .map(|us| heard.clock.local_time_of(us))
                .filter(|t| *t >= self.round_since)
        });
        self.proposal
            .into_iter()
            .chain(others)
            .filter(|t| self.void_until.is_none_or(|v| *t > v))
            .min()
    }

    /// Whether every other shard's latest report vouches for `instant`.
    fn all_agree(&self, instant: SimTime, heard: Heard<'_>) -> bool {
        let us = heard.clock.to_swarm_us(instant);
        heard.reports.iter().enumerate().all(|(s, r)| {
            s == self.this
                || r.as_ref()
                    .is_some_and(|(_, r)| r.start_us == Some(us) && r.planned == self.planned)
        })
    }

    /// With every vehicle flying in this shard's view: whether the instant is due on
    /// this tick (this shard proposes one first). An instant that comes without every
    /// shard's word is void: this shard proposes anew.
    pub(super) fn due(&mut self, now: SimTime, heard: Heard<'_>) -> bool {
        if self
            .proposal
            .is_none_or(|t| self.void_until.is_some_and(|v| t <= v))
        {
            self.proposal = Some(now + self.lead);
        }
        self.agreed = self.adopted(heard);
        match self.agreed {
            Some(t) if now >= t => {
                if self.all_agree(t, heard) {
                    return true;
                }
                self.void_until = Some(now);
                self.proposal = Some(now + self.lead);
                self.agreed = self.adopted(heard);
                false
            }
            _ => false,
        }
    }

    /// Not every vehicle flies in this shard's view: it vouches for nothing (its
    /// proposal stays, for when they fly again). Nothing changes once started.
    pub(super) fn withdraw(&mut self) {
        if self.started.is_none() {
            self.agreed = None;
        }
    }

    /// The instant is due: started at the adopted instant (or `now`, if none), with
    /// this shard's sum `own`; returns the instant.
    pub(super) fn start(&mut self, now: SimTime, own: WeightedSum, heard: Heard<'_>) -> SimTime {
        let start = self.adopted(heard).unwrap_or(now);
        self.started = Some((start, own));
        self.predicted = false;
        start
    }

    /// Whether the prediction of this round is still to be made (started, not predicted).
    pub(super) fn awaits_prediction(&self) -> Option<(SimTime, WeightedSum)> {
        self.started.filter(|_| !self.predicted)
    }

    /// The prediction of this round was made.
    pub(super) fn set_predicted(&mut self) {
        self.predicted = true;
    }

    /// Whether `r`, sent well after this shard started, shows that its shard did not
    /// start at the same instant (it missed the agreement): the swarm is split.
    pub(super) fn started_without(&self, r: &ShardReport, clock: SwarmClock) -> bool {
        let Some((start, _)) = self.started else {
            return false;
        };
        let start_us = clock.to_swarm_us(start);
        !r.ended
            && r.sent_us > start_us.saturating_add(AGREEMENT_SETTLED.as_micros() as u64)
            && r.start_us != Some(start_us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEAD: Duration = Duration::from_millis(500);
    const CLOCK: SwarmClock = SwarmClock {
        epoch_us: 1_000_000,
    };

    fn ms(t: u64) -> SimTime {
        SimTime::from_millis(t)
    }

    /// Shard `shard`'s report vouching for `start` (this shard's time), sent at `sent`.
    fn report(shard: u16, sent: SimTime, start: Option<SimTime>) -> (SimTime, ShardReport) {
        let r = ShardReport {
            shard,
            sent_us: CLOCK.to_swarm_us(sent),
            vehicles: 2,
            flying: 2,
            lost: 0,
            ended: false,
            start_us: start.map(|t| CLOCK.to_swarm_us(t)),
            start_sum: None,
            now_sum: WeightedSum::default(),
            top_speed_mps: 0.0,
            planned: false,
            plan_velocities: None,
            places_assigned: false,
            start_positions: None,
        };
        (sent, r)
    }

    fn heard(reports: &[Option<(SimTime, ShardReport)>]) -> Heard<'_> {
        Heard {
            reports,
            clock: CLOCK,
        }
    }

    #[test]
    fn the_swarm_clock_and_the_local_time_are_inverse() {
        assert_eq!(CLOCK.to_swarm_us(ms(250)), 1_250_000);
        assert_eq!(CLOCK.local_time_of(1_250_000), ms(250));
        // Before this shard's zero: its zero, not a wrap.
        assert_eq!(CLOCK.local_time_of(10), SimTime::ZERO);
    }

    #[test]
    fn the_earliest_proposal_is_adopted_and_started_when_every_shard_vouches() {
        let mut a = StartAgreement::new(0, LEAD);
        // The other shard proposed 1.3 s; this one proposes 1.0 + 0.5 = 1.5 s.
        let mut reports = vec![None, Some(report(1, ms(1000), Some(ms(1300))))];
        assert!(!a.due(ms(1000), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(1300)));
        assert!(a.proposed());
        // At 1.3 s the other shard still vouches for 1.3 s: due.
        reports[1] = Some(report(1, ms(1290), Some(ms(1300))));
        assert!(a.due(ms(1300), heard(&reports)));
        let own = WeightedSum {
            wp_m: [1.0, 2.0],
            wv_mps: [3.0, 4.0],
            w: 0.5,
        };
        assert_eq!(a.start(ms(1304), own, heard(&reports)), ms(1300));
        assert_eq!(a.started(), Some((ms(1300), own)));
        assert_eq!(a.awaits_prediction(), Some((ms(1300), own)));
        a.set_predicted();
        assert_eq!(a.awaits_prediction(), None);
    }

    #[test]
    fn an_instant_without_every_shards_word_is_void_and_proposed_anew() {
        let mut a = StartAgreement::new(0, LEAD);
        // The other shard vouches for nothing (it sees a vehicle down).
        let reports = vec![None, Some(report(1, ms(900), None))];
        assert!(!a.due(ms(1000), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(1500)));
        // 1.5 s comes unvouched: void; the new proposal is 1.5 + 0.5 = 2.0 s.
        assert!(!a.due(ms(1500), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(2000)));
        // A late report vouching for the void 1.5 s is not taken.
        let late = vec![None, Some(report(1, ms(1600), Some(ms(1500))))];
        assert_eq!(a.adopted(heard(&late)), Some(ms(2000)));
    }

    #[test]
    fn a_new_round_forgets_the_proposals_of_the_last() {
        let mut a = StartAgreement::new(0, LEAD);
        let reports = vec![None, Some(report(1, ms(900), Some(ms(1200))))];
        assert!(!a.due(ms(1000), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(1200)));
        a.new_round(ms(3000));
        assert!(!a.proposed());
        assert_eq!(a.vouched(), None);
        // The 1.2 s of the last round is before this round: only the own 3.5 s counts.
        assert!(!a.due(ms(3000), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(3500)));
    }

    #[test]
    fn plan_instants_and_consensus_starts_are_never_mixed() {
        let mut a = StartAgreement::new(0, LEAD);
        a.set_planned();
        // The other shard has not planned: its 1.1 s is a plan instant.
        let reports = vec![None, Some(report(1, ms(900), Some(ms(1100))))];
        assert!(!a.due(ms(1000), heard(&reports)));
        assert_eq!(a.vouched(), Some(ms(1500)));
    }

    #[test]
    fn a_withdrawn_shard_vouches_for_nothing_until_started() {
        let mut a = StartAgreement::new(1, LEAD);
        let reports = vec![Some(report(0, ms(900), None)), None];
        assert!(!a.due(ms(1000), heard(&reports)));
        a.withdraw();
        assert_eq!(a.vouched(), None);
        assert!(
            a.proposed(),
            "the proposal stays for when every vehicle flies again"
        );
        a.start(ms(1500), WeightedSum::default(), heard(&reports));
        a.withdraw();
        assert_eq!(a.vouched(), Some(ms(1500)));
    }

    #[test]
    fn a_shard_that_missed_the_start_is_seen_once_the_agreement_settled() {
        let mut a = StartAgreement::new(0, LEAD);
        a.start(ms(2000), WeightedSum::default(), heard(&[None, None]));
        let settled = ms(2000) + AGREEMENT_SETTLED;
        let (_, early) = report(1, settled, None);
        assert!(
            !a.started_without(&early, CLOCK),
            "sent within the settling time"
        );
        let (_, late) = report(1, settled + Duration::from_millis(1), None);
        assert!(a.started_without(&late, CLOCK));
        let (_, same) = report(1, settled + Duration::from_millis(1), Some(ms(2000)));
        assert!(!a.started_without(&same, CLOCK));
        let (_, mut over) = report(1, settled + Duration::from_millis(1), None);
        over.ended = true;
        assert!(
            !a.started_without(&over, CLOCK),
            "a shard whose flight ended"
        );
    }
}
