//! `chladni`: the command-line tool of the Chladni parts feeder.
use clap::Parser;

mod cli;
mod demo;

fn main() -> std::process::ExitCode {
    quiet_on_closed_stdout();
    let json = cli::wants_json(std::env::args_os().skip(1));
    let cli = match cli::Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // Usage errors with --json: the one JSON object too (help and version are no
            // failure and print as usual).
            if json && e.use_stderr() {
                cli::print_failure_json("usage", &e.render().to_string());
            }
            e.exit()
        }
    };
    match cli.run() {
        Ok(code) => code,
        Err(err) => {
            let code = cli::exit_code_of(&err);
            if json && !cli::failure_json_printed() {
                let kind = if code == 2 { "bad_input" } else { "failed" };
                cli::print_failure_json(kind, &format!("{err:#}"));
            }
            eprintln!("error: {err:#}");
            std::process::ExitCode::from(code)
        }
    }
}

/// `chladni … | head` closes stdout early; `println!` then panics with "failed printing to
/// stdout: Broken pipe". That is the reader's choice, not a failure: end quietly with 0, as
/// Unix tools do, and leave every other panic to the default hook.
fn quiet_on_closed_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info);
    }));
}
