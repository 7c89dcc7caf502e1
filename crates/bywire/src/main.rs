//! The `bywire` binary: the command line of the `bywire` library crate.

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(bywire::run(std::env::args_os()))
}
