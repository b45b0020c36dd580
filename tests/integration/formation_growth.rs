//! The formation error's growth rate in `summary.json` against the theory: flown in
//! lockstep from paper-sim1's start with other gains, the rate fitted over the later
//! half of the consensus is the closed loop's spectral abscissa that `analyze` computes
//! (itself checked against numpy in `paper_examples.rs`), on both sides of the stability
//! boundary. The theory is the ideal double integrator; the flown loop adds the control
//! period and the vehicles' attitude response, which shift its slowest mode by a few
//! thousandths of 1/s, so the test holds the sign and the order, not the value.

use ringswarm::config::Config;
use ringswarm::consensus::{CouplingGains, RingDigraph, analyze};

/// paper-sim1 with ring gain `k` and velocity gain `beta`, 60 s of consensus: its
/// growth rate, the abscissa of its closed loop (1/s) and its exit code.
fn flown_and_theory(k: f64, beta: f64) -> (f64, f64, u8) {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/paper-sim1.toml"
    ))
    .expect("paper-sim1.toml");
    let mut config = Config::from_toml(&text).expect("paper-sim1 parses");
    config.gains.k = k;
    config.gains.beta = beta;
    config.swarm.duration_s = 60.0;
    let g = &config.gains;
    let c = g.time_scale;
    let ring = RingDigraph::for_agents(config.vehicle.len(), g.k).expect("ring");
    let gains = CouplingGains::new(g.alpha * c * c, g.beta * c).expect("gains");
    let theory = analyze(&ring, Some(gains))
        .expect("analyze")
        .gain_check
        .expect("gains checked")
        .closed_loop_abscissa;
    let flown = ringswarm::sweep::fly(&config).expect("flies");
    let rate = flown.summary.formation_growth_per_s.expect("a growth rate");
    eprintln!(
        "k {k} beta {beta}: flown {rate:.5} 1/s, theory {theory:.5} 1/s, exit {}",
        flown.exit_code
    );
    (rate, theory, flown.exit_code)
}

#[test]
fn the_growth_rate_has_the_closed_loop_abscissas_sign_and_order_where_the_flight_ran_out() {
    // k = 3 across its boundary (analyze: beta = 0.9604): a slowly growing formation
    // just below it runs its 60 s out (the guard does not see it), and the rate says it.
    let mut last = f64::INFINITY;
    for beta in [0.919, 1.066, 1.235, 1.432] {
        let (flown, theory, exit) = flown_and_theory(3.0, beta);
        assert_eq!(exit, 0, "k 3 beta {beta}");
        assert_eq!(
            flown > 0.0,
            theory > 0.0,
            "k 3 beta {beta}: {flown} against {theory}"
        );
        // The larger beta, the faster the formation closes, flown as in theory.
        assert!(flown < last, "k 3 beta {beta}: {flown} after {last}");
        last = flown;
    }
    // k = 1 (boundary at 0.8895): stable above it; below it the flight runs away and
    // the guard ends it, before the growing mode outweighs the decaying ones in the
    // formation error (which is why a map of the rate requires exit 0).
    let (flown, theory, exit) = flown_and_theory(1.0, 1.432);
    assert!(
        exit == 0 && flown < 0.0 && theory < 0.0,
        "{flown} {theory} {exit}"
    );
    let (_, theory, exit) = flown_and_theory(1.0, 0.793);
    assert!(theory > 0.0 && exit == 4, "{theory} {exit}");
}
