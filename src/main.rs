//! The `prismap` command line: parse, then hand over to one command (see `cli`).

use clap::Parser;

use prismap::cli::{Cli, Command, commands};
use prismap::{app, scene};

/// Every pass allocates and frees its photon maps, irradiance cache and image (tens of
/// MB). glibc's allocator handed that memory back to the OS between passes and faulted it
/// in again (a pass's photon tracing took 95–180 ms depending on what the previous pass
/// had freed; up to a quarter of the samples in `clear_page`). mimalloc, told never to
/// purge (`mi_option_purge_delay` = −1, set first thing in `main`), keeps it: the process
/// holds its peak, which it reaches in the first pass anyway.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// `mi_option_purge_delay` in `mi_option_e`: 15 in mimalloc 2 and in mimalloc 3 (which
/// libmimalloc-sys 0.1.49 builds by default); the crate names the options around it, 14
/// `eager_commit_delay` and 16 `use_numa_nodes`, but not this one.
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

fn main() {
    // SAFETY: sets a process-wide allocator option; mimalloc reads it at each purge.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
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
