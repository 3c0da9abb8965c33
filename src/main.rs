//! The `prismap` command line: parse, then hand over to one command (see `cli`).

use clap::Parser;

use prismap::cli::{Cli, Command, commands};
use prismap::{app, scene};

mod allocator;

fn main() {
    allocator::keep_freed_memory();
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::View(args)) => commands::view(args),
        Some(Command::Render(args)) => commands::render(*args),
        Some(Command::Report(args)) => commands::report(args),
        Some(Command::List) => {
            commands::list();
            Ok(())
        }
        None if app::display_available() => match Cli::parse_from(["prismap", "view"]).command {
            Some(Command::View(args)) => commands::view(args),
            _ => unreachable!("`prismap view` parses as the view command"),
        },
        None => {
            eprintln!(
                "prismap: no display, so rendering the built-in '{}' scene headless instead of opening the viewer (see `prismap --help`).",
                scene::DEFAULT_SCENE
            );
            match Cli::parse_from(["prismap", "render"]).command {
                Some(Command::Render(args)) => commands::render(*args),
                _ => unreachable!("`prismap render` parses as the render command"),
            }
        }
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
