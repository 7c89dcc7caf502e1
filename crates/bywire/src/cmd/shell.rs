//! `bywire completions` and `bywire man`: the shell's completions and the manual pages, both
//! generated from the command line's own definition (so they are never out of date).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap_complete::Shell;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire completions bash > ~/.local/share/bash-completion/completions/bywire
  bywire completions zsh > ~/.zfunc/_bywire
  bywire completions fish > ~/.config/fish/completions/bywire.fish")]
pub struct CompletionsArgs {
    /// The shell: bash, zsh, fish, elvish or powershell.
    shell: Shell,
}

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire man ~/.local/share/man/man1 && man bywire-dump")]
pub struct ManArgs {
    /// The folder the pages are written into (created if missing): bywire.1 and one page per
    /// command, bywire-dump.1, bywire-log-convert.1, …
    dir: PathBuf,
}

/// Print the completion script for `args.shell` of the command line `cli`.
pub fn completions(
    args: &CompletionsArgs,
    mut cli: clap::Command,
    out: &mut dyn Write,
) -> Result<()> {
    // Made in memory first: clap_complete panics when its writer fails (a closed pipe), where
    // our write gives the error back (and a closed pipe is no failure).
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut cli, "bywire", &mut script);
    out.write_all(&script)?;
    Ok(())
}

/// Write a manual page for `cli` and for each of its commands, at every depth.
pub fn man(args: &ManArgs, cli: clap::Command, out: &mut dyn Write) -> Result<()> {
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("cannot create {}", args.dir.display()))?;
    let mut written = 0u64;
    write_pages(&args.dir, cli, "bywire", &mut written)?;
    writeln!(
        out,
        "{} in {}",
        crate::support::words::counted(written, "page"),
        args.dir.display()
    )?;
    Ok(())
}

/// `command`'s page as `name.1`, then its subcommands' as `name-SUB.1` (the depth is the
/// command line's own, three at most).
fn write_pages(dir: &Path, command: clap::Command, name: &str, written: &mut u64) -> Result<()> {
    let command = command
        .display_name(name.to_string())
        .bin_name(name.replace('-', " "));
    let mut page = Vec::new();
    clap_mangen::Man::new(command.clone())
        .render(&mut page)
        .with_context(|| format!("the page of {name}"))?;
    let path = dir.join(format!("{name}.1"));
    crate::support::files::write_atomically(&path, |tmp| {
        std::fs::write(tmp, &page).with_context(|| format!("cannot write {}", path.display()))
    })?;
    *written += 1;
    for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
        write_pages(
            dir,
            sub.clone(),
            &format!("{name}-{}", sub.get_name()),
            written,
        )?;
    }
    Ok(())
}
