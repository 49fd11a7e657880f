//! The `flexdyn` command line: parses the arguments and hands each command to
//! its module in `flexdyn::cli`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use flexdyn::cli;

/// Exact, allocation-free equations of motion for rigid and flexible
/// multibody systems, generated from scene files.
#[derive(Parser)]
#[command(name = "flexdyn", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Generate(cli::generate::Args),
    Export(cli::export::Args),
    Eval(cli::eval::Args),
    Simulate(Box<cli::simulate::Args>),
    Inverse(cli::inverse::Args),
    Linearize(cli::linearize::Args),
    Import(cli::import::Args),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Generate(args) => cli::generate::run(&args),
        Command::Export(args) => cli::export::run(&args),
        Command::Eval(args) => cli::eval::run(&args, &flexdyn::compiled::COMPILED_SCENES),
        Command::Simulate(args) => cli::simulate::run(&args, &flexdyn::compiled::COMPILED_SCENES),
        Command::Inverse(args) => cli::inverse::run(&args, &flexdyn::compiled::COMPILED_SCENES),
        Command::Linearize(args) => cli::linearize::run(&args, &flexdyn::compiled::COMPILED_SCENES),
        Command::Import(args) => cli::import::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
