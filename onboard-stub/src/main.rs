//! `oils-onboard-stub`: the onboard-computer process, started by hand to join a run
//! (`oils-emulator` prints the command), or spawned by `oils run`.

use anyhow::Context;
use clap::Parser;
use oils_onboard_stub::cli::{run_stub, StubArgs};

#[derive(Parser)]
#[command(
    name = "oils-onboard-stub",
    version,
    about = "Onboard-computer stub of the oils bench"
)]
struct Cli {
    #[command(flatten)]
    args: StubArgs,
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
    let s = run_stub(&cli.args, &stop)
        .with_context(|| format!("onboard stub on run {}", cli.args.run_id))?;
    eprintln!(
        "oils-onboard-stub: served {} commands, last step {}",
        s.commands, s.last_step
    );
    Ok(())
}
