//! `oils`: the onboard-in-loop simulation bench for a lunar lander.

mod cmd;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "oils",
    version,
    about = "Onboard-in-loop simulation bench for a lunar lander"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the high-fidelity propulsion model open loop from a thrust profile, or draw
    /// its figures.
    Hifi(cmd::hifi::HifiArgs),
}

fn main() {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Hifi(args) => cmd::hifi::run(args),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
