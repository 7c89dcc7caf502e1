//! Who may reach a server this program starts (`serve`, `web`, `--foxglove`): loopback is
//! open; another address needs `--allow-remote` and a token, which comes from a file or the
//! environment, never the command line (every user of the host can read that).

use std::net::SocketAddr;
use std::path::Path;

use anyhow::{anyhow, Context, Result};

/// The environment variable a token may come from.
pub const TOKEN_VARIABLE: &str = "BYWIRE_SERVE_TOKEN";

/// The options of a server that may listen beyond this host.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct Remote {
    /// Allow listening on an address other hosts can reach (needs a token).
    #[arg(long)]
    pub allow_remote: bool,
    /// Require a token, read from this file's first line (or from BYWIRE_SERVE_TOKEN):
    /// socketcand clients send `< auth TOKEN >` first (plain ones cannot: for bywire clients
    /// and scripts), pages are opened as /?token=TOKEN and Foxglove clients add ?token=TOKEN
    /// to the address. A wrong token closes the connection; attempts are paced.
    #[arg(long, value_name = "PATH")]
    pub token_file: Option<std::path::PathBuf>,
    /// Refused: a token on the command line is visible to every user of the host.
    #[arg(long, value_name = "TOKEN", hide = true)]
    pub token: Option<String>,
}

impl Remote {
    /// The token, as [`token`] reads it.
    pub fn token(&self) -> Result<Option<String>> {
        token(self.token.is_some(), self.token_file.as_deref())
    }

    /// Refuse `listen` (of option `option`) as [`check_listen`] does.
    pub fn check(
        &self,
        option: &str,
        listen: SocketAddr,
        token: Option<&str>,
        protocol: &str,
    ) -> Result<()> {
        check_listen(option, listen, self.allow_remote, token, protocol)
    }
}

/// The token from `token_file` (its first line) or the environment; `None` for an open
/// server. `on_command_line`: a token given as an option, which is refused.
pub fn token(on_command_line: bool, token_file: Option<&Path>) -> Result<Option<String>> {
    if on_command_line {
        return Err(anyhow!(
            "--token: a token on the command line is visible to every user of this host; put it in a file (--token-file PATH) or in {TOKEN_VARIABLE}"
        ));
    }
    let token = match token_file {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("--token-file {}", path.display()))?;
            Some(text.lines().next().unwrap_or("").trim().to_string())
        }
        None => std::env::var(TOKEN_VARIABLE).ok(),
    };
    match token {
        Some(token) if token.chars().count() < 8 || token.contains(char::is_whitespace) => Err(
            anyhow!("the token must be at least 8 characters, without spaces"),
        ),
        other => Ok(other),
    }
}

/// Refuse to listen beyond this host unless asked to (`allow_remote`) and given a token.
/// `option`: the listening option's name; `protocol`: what clients speak, for the message.
pub fn check_listen(
    option: &str,
    listen: SocketAddr,
    allow_remote: bool,
    token: Option<&str>,
    protocol: &str,
) -> Result<()> {
    if listen.ip().is_loopback() {
        return Ok(());
    }
    if !allow_remote {
        return Err(anyhow!(
            "{option} {listen}: not a loopback address; {protocol}, so add --allow-remote and a token to serve other hosts"
        ));
    }
    if token.is_none() {
        return Err(anyhow!(
            "--allow-remote: other hosts may reach this server only with a token (--token-file PATH or {TOKEN_VARIABLE})"
        ));
    }
    Ok(())
}
