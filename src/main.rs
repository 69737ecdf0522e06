//! The `seam` binary: parse the command line, run, turn the outcome into an
//! exit code. Everything else lives in `seam::cli`.

fn main() -> std::process::ExitCode {
    restore_default_sigpipe();
    seam::cli::tune_allocator();
    seam::cli::main()
}

/// `seam query … | head` closes stdout early. Rust ignores SIGPIPE, so the
/// next `println!` would panic with "failed printing to stdout: Broken pipe";
/// with the default disposition the process ends quietly, as `cat` does.
#[cfg(unix)]
fn restore_default_sigpipe() {
    // SAFETY: called first thing in `main`, before any thread exists; setting a
    // signal's disposition to its default has no other preconditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_default_sigpipe() {}
