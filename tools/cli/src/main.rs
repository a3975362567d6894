//! `relevo`: turn raw elevation tiles and imagery into a terrain bundle.

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    // Output piped into a reader that stops early (`relevo info B | head`)
    // ends the process quietly, as other command-line tools do, instead of
    // a panic on the failed write.
    // SAFETY: called first, before any thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = relevo::commands::Cli::parse();
    relevo::commands::init_logging(cli.verbose, cli.quiet);
    relevo::ingest::gdalio::init();
    match relevo::commands::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            match error.downcast_ref::<relevo::commands::Exit>() {
                Some(exit) => ExitCode::from(exit.code),
                None => ExitCode::FAILURE,
            }
        }
    }
}
