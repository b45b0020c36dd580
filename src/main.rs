//! The `ringswarm` binary: parse the command line, install tracing, dispatch.
//!
//! Exit codes: 0 for a stable / feasible answer or a flight that went as configured, 1
//! for an unstable / infeasible one, 2 for a usage error (clap's own, or a value our
//! validation refuses), 3 when `fly` or `demo` gave up before the flight (a handshake
//! not complete within `swarm.handshake_timeout_s`: the vehicles not flying are named,
//! the others were landed), 4 when the divergence guard ended the consensus of `fly` or
//! `demo` (the swarm ran away from the law's prediction; `summary.json` names the cause).
//!
//! Logging: `RUST_LOG` as usual; unset, warnings and the swarm's warning events (lost,
//! refused, timeouts, failsafes, origin changes) are printed.

use std::process::ExitCode;

use clap::Parser;
use ringswarm::cli::{Cli, Command};
use ringswarm::cmd;
use tracing_subscriber::EnvFilter;
use tracing_subscriber::filter::LevelFilter;

fn main() -> ExitCode {
    if let Some(missing) = missing_cpu_features() {
        eprintln!(
            "error: this build of ringswarm needs x86-64-v3, and this processor lacks {missing}; \
             rebuild it with RUSTFLAGS=\"-C target-cpu=x86-64\" (.cargo/config.toml)"
        );
        return ExitCode::from(2);
    }
    let cli = Cli::parse();
    // A sweep flies thousands of flights: their swarm events (what a single flight
    // prints) would bury its progress. They are in each flight's row, and `sweep --cell`
    // prints them for one; RUST_LOG still shows them.
    #[cfg(feature = "emulator")]
    let quiet = matches!(&cli.command, Command::Sweep(a) if a.cell.is_none());
    #[cfg(not(feature = "emulator"))]
    let quiet = false;
    let mut filter = EnvFilter::builder()
        .with_default_directive(LevelFilter::WARN.into())
        .from_env_lossy();
    if quiet
        && std::env::var_os("RUST_LOG").is_none()
        && let Ok(directive) = "ringswarm_core::swarm::events=error".parse()
    {
        filter = filter.add_directive(directive);
    }
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Analyze(args) => cmd::analyze::run(&args),
        Command::Plan(args) => cmd::plan::run(&args),
        #[cfg(feature = "emulator")]
        Command::Sitl(args) => cmd::sitl::run(&args).map(|()| true),
        Command::Fly(args) => cmd::fly::run(&args).map(|()| true),
        #[cfg(feature = "emulator")]
        Command::Demo(args) => cmd::demo::run(&args).map(|()| true),
        #[cfg(feature = "emulator")]
        Command::Sweep(args) => cmd::sweep::run(&args).map(|()| true),
        Command::Keygen(args) => cmd::keygen::run(&args.file).map(|()| true),
        Command::SignSetup(args) => cmd::sign_setup::run(&args).map(|()| true),
        Command::View(args) => cmd::view::run(&args).map(|()| true),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(ringswarm::error::code_of(&err))
        }
    }
}

/// The processor features the build was compiled to use (`.cargo/config.toml`) that this
/// processor lacks, named; `None` when it has them all (or the build assumes none).
fn missing_cpu_features() -> Option<String> {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        let mut missing = Vec::new();
        macro_rules! need {
            ($($f:tt),*) => {
                $(if !std::arch::is_x86_feature_detected!($f) {
                    missing.push($f);
                })*
            };
        }
        need!(
            "avx", "avx2", "fma", "bmi1", "bmi2", "lzcnt", "movbe", "f16c"
        );
        if !missing.is_empty() {
            return Some(missing.join(", "));
        }
    }
    None
}
