//! `relevo`: turn raw elevation tiles and imagery into a terrain bundle.

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = relevo::cli::Cli::parse();
    relevo::cli::init_logging(cli.verbose, cli.quiet);
    relevo::gdalio::init();
    match relevo::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
