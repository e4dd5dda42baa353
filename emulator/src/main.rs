//! `oils-emulator`: the emulator process on its own. It creates the run's services,
//! prints the command that starts a stub (or your own flight software) in a second
//! terminal, waits for it, and runs.

use anyhow::Context;
use clap::Parser;
use oils_emulator::session::{run_session, RunArgs};

#[derive(Parser)]
#[command(
    name = "oils-emulator",
    version,
    about = "Emulator process of the oils bench"
)]
struct Cli {
    #[command(flatten)]
    args: RunArgs,
}

/// Errors print as one chain of causes (no backtrace, whatever RUST_BACKTRACE says)
/// and exit with status 1.
fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn real_main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let report = run_session(&cli.args, &stop, &mut |run_id, _wait| {
        eprintln!(
            "oils-emulator: run {run_id:016x} is waiting for an onboard stub; start one with:"
        );
        eprintln!("    cargo run --release -p oils-onboard-stub -- --run-id {run_id:016x}");
        Ok(())
    })
    .context("emulator run")?;
    Ok(oils_emulator::report::finish_run(
        &report,
        cli.args.report.as_deref(),
    )?)
}
