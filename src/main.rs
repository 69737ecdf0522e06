//! The `seam` binary: parse the command line, run, turn the outcome into an
//! exit code. Everything else lives in `seam::cli`.

fn main() -> std::process::ExitCode {
    seam::cli::main()
}
