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
use ringswarm::error::{FenceStopped, GaveUp, GuardStopped, SeparationStopped};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::filter::LevelFilter;

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::builder()
                .with_default_directive(LevelFilter::WARN.into())
                .from_env_lossy(),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Analyze(args) => cmd::analyze::run(&args),
        Command::Plan(args) => cmd::plan::run(&args),
        #[cfg(feature = "emulator")]
        Command::Sitl(args) => cmd::sitl::run(&args).map(|()| true),
        Command::Fly(args) => cmd::fly::run(&args).map(|()| true),
        #[cfg(feature = "emulator")]
        Command::Demo(args) => cmd::demo::run(&args).map(|()| true),
        Command::Keygen(args) => cmd::keygen::run(&args.file).map(|()| true),
        Command::SignSetup(args) => cmd::sign_setup::run(&args).map(|()| true),
        Command::View(args) => cmd::view::run(&args).map(|()| true),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(err) => {
            eprintln!("error: {err:#}");
            if err.downcast_ref::<GaveUp>().is_some() {
                ExitCode::from(GaveUp::EXIT_CODE)
            } else if err.downcast_ref::<GuardStopped>().is_some() {
                ExitCode::from(GuardStopped::EXIT_CODE)
            } else if err.downcast_ref::<FenceStopped>().is_some() {
                ExitCode::from(FenceStopped::EXIT_CODE)
            } else if err.downcast_ref::<SeparationStopped>().is_some() {
                ExitCode::from(SeparationStopped::EXIT_CODE)
            } else {
                ExitCode::from(2)
            }
        }
    }
}
