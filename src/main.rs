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
use ringswarm::cli::{AnalyzeArgs, Cli, Command, PlanArgs};
use ringswarm::consensus::PlanRequest;
use ringswarm::error::{FenceStopped, GaveUp, GuardStopped, SeparationStopped};
use ringswarm::report::{AnalyzeRequest, emit, run_analyze, run_plan_everyone};
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
        Command::Analyze(args) => analyze(&args),
        Command::Plan(args) => plan(&args),
        #[cfg(feature = "emulator")]
        Command::Sitl(args) => ringswarm::sitl_cmd::run(&args).map(|()| true),
        Command::Fly(args) => ringswarm::fly_cmd::run(&args).map(|()| true),
        #[cfg(feature = "emulator")]
        Command::Demo(args) => ringswarm::demo_cmd::run(&args).map(|()| true),
        Command::Keygen(args) => keygen(&args.file).map(|()| true),
        Command::SignSetup(args) => ringswarm::sign_setup_cmd::run(&args).map(|()| true),
        Command::View(args) => ringswarm::view_cmd::run(&args).map(|()| true),
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

/// Writes a new signing key and says where.
fn keygen(path: &std::path::Path) -> anyhow::Result<()> {
    let key = ringswarm_wire::signing::SigningKey::generate().map_err(anyhow::Error::msg)?;
    key.write_new(path).map_err(anyhow::Error::msg)?;
    eprintln!(
        "signing key written to {} (mode 0600); keep it secret",
        path.display()
    );
    Ok(())
}

/// Prints the analysis; `Ok(stable)`.
fn analyze(args: &AnalyzeArgs) -> anyhow::Result<bool> {
    let output = run_analyze(&AnalyzeRequest {
        macro_vertices: args.macro_vertices,
        k: args.k,
        gains: args.alpha.zip(args.beta),
        design_k: args.design_k,
        gain_margin: args.gain_margin,
        airframe: args.attitude_bandwidth.map(|a| (a, args.control_rate)),
        list_eigenvalues: args.eigenvalues,
    })?;
    if args.json {
        emit(&serde_json::to_string_pretty(&output)?)?;
    } else {
        emit(&output.to_string())?;
    }
    Ok(output.stable)
}

/// Prints the plan; `Ok(feasible)`.
fn plan(args: &PlanArgs) -> anyhow::Result<bool> {
    let output = run_plan_everyone(
        &PlanRequest {
            velocities_mps: args.initial_velocities.0.clone(),
            target_mps: args.target,
            k_margin: args.margin,
            k_max: args.k_max,
            max_speed_mps: args.max_speed,
        },
        args.k,
    )?;
    if args.json {
        emit(&serde_json::to_string_pretty(&output)?)?;
    } else {
        emit(&output.to_string())?;
    }
    Ok(output.feasible)
}
