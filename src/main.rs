//! `oils`: the one-command bench. This branch carries only the `train` subcommand; the
//! lead merges it into the full command set.

mod cmd;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "oils",
    version,
    about = "Onboard-in-loop simulation bench for a lunar lander"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Train the propulsion surrogate (seed paper): excitation, data, Lasso, CV, model file.
    Train(cmd::train::TrainArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Train(args) => cmd::train::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
