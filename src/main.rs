//! FlareLab: the desktop app with no arguments, the command line with a subcommand.
//!
//! Errors on the command line end the program with exit code 2 and one line on stderr; a panic (a bug) is
//! reported the same way instead of a backtrace.

use std::process::ExitCode;

use flarelab::{app, cli};

/// Gives the libraries a runtime folder when the session has none. Vulkan's window-system layer asks
/// libwayland for a display on every GPU device made, and libwayland prints "error: XDG_RUNTIME_DIR is invalid
/// or not set in the environment." when the variable is missing (a container, ssh, cron), although nothing is
/// wrong and no window is wanted. Where it is unset or not a folder, it becomes a private folder of the user's
/// under the temporary folder (`flarelab-runtime-UID`, mode 0700, as the XDG specification asks), made once; a
/// folder that cannot be made leaves the environment as it was (the line is then printed, nothing else fails).
#[cfg(target_os = "linux")]
fn give_libraries_a_runtime_dir() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|dir| std::path::Path::new(&dir).is_dir()) {
        return;
    }
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let dir = std::env::temp_dir().join(format!("flarelab-runtime-{uid}"));
    let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    // Only a folder that is the user's own and private (another user could have made one of that name first).
    let Ok(meta) = std::fs::symlink_metadata(&dir) else { return };
    if !meta.is_dir() || meta.uid() != uid || meta.permissions().mode() & 0o077 != 0 {
        return;
    }
    // SAFETY: called first thing in `main`, before any thread exists, so nothing reads the environment while it
    // changes.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
}

#[cfg(not(target_os = "linux"))]
fn give_libraries_a_runtime_dir() {}

fn main() -> ExitCode {
    give_libraries_a_runtime_dir();
    std::panic::set_hook(Box::new(|info| {
        // A panic the core contains becomes an error that names it (`output::panic_is_contained`).
        if flare_core::output::panic_is_contained() {
            return;
        }
        let message = flare_core::output::panic_message(info.payload()).unwrap_or_else(|| "unknown".to_owned());
        // `flarelab ... | head` closes the pipe early: that is the reader's choice, not a bug.
        if message.starts_with("failed printing to stdout") {
            std::process::exit(0);
        }
        let place = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
        eprintln!("flarelab: internal error (a bug; please report it): {}{place}", message.replace('\n', " "));
    }));
    // A negative number is a value on every command (`--f-number -2` is then refused by its own check, naming
    // the flag, instead of clap's "unexpected argument").
    fn allow_negatives(command: clap::Command) -> clap::Command {
        command.allow_negative_numbers(true).mut_subcommands(allow_negatives)
    }
    use clap::{CommandFactory, FromArgMatches};
    let parsed =
        allow_negatives(cli::Cli::command()).try_get_matches().and_then(|matches| cli::Cli::from_arg_matches(&matches));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            // One line, as every other error: clap's first line, without its own "error: " prefix.
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or("invalid arguments").trim_start_matches("error: ");
            // The indented lines that follow it (the missing arguments, an enumerated flag's possible values)
            // belong to the one line too.
            let listed: Vec<&str> = text
                .lines()
                .skip(1)
                .take_while(|l| l.starts_with("  ") && !l.trim().is_empty())
                .map(str::trim)
                .collect();
            let first = if listed.is_empty() { first.to_owned() } else { format!("{first} {}", listed.join(", ")) };
            eprintln!("flarelab: error: {} (see `flarelab --help`)", printable(&first));
            return ExitCode::from(2);
        }
    };
    for path in &cli.catalogs {
        if let Err(e) = flare_core::optics::formats::load_glass_catalogue(path) {
            eprintln!("flarelab: error: --catalog {}", printable(&e));
            return ExitCode::from(2);
        }
    }
    let result = match cli.command {
        None => app::run(),
        Some(command) => cli::run(command),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("flarelab: error: {}", printable(&chain_text(&e).replace('\n', " ")));
            ExitCode::from(2)
        }
    }
}

/// An error for the terminal: control characters (from a file name or a file's contents) escaped, so no input
/// can move the cursor, clear the screen or ring the bell.
fn printable(text: &str) -> String {
    text.chars().flat_map(|c| if c.is_control() { c.escape_default().collect::<Vec<_>>() } else { vec![c] }).collect()
}

/// An error and its causes joined by ": ", a cause left out when the text before it already says it (an error
/// whose message is its source's would otherwise say it twice).
fn chain_text(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let said = cause.to_string();
        if text.contains(&said) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&said);
    }
    text
}
