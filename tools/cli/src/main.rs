//! `relevo`: turn raw elevation tiles and imagery into a terrain bundle.

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = relevo::commands::Cli::parse();
    relevo::commands::init_logging(cli.verbose, cli.quiet);
    relevo::ingest::gdalio::init();
    match relevo::commands::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
