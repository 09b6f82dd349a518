fn main() {
    passive_openmp();
    // A reader that stops early (`garmentbake inspect M | head -1`) ends us quietly, as it ends
    // any Unix tool, instead of `println!` panicking on the broken pipe.
    // SAFETY: restoring the default disposition of one signal before any thread starts.
    unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    let code = garmentbake::cli::main();
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    // Leave without running C++ static destructors: usd-core's worker threads (TBB) can still be
    // live inside the embedded Python when they run, and a crash there (seen once in the test
    // suite, after a correct report was printed) would turn exit code 1 into a signal. Every
    // output is already written atomically and flushed.
    // SAFETY: `_exit` ends the process at once; nothing after it runs.
    unsafe { libc::_exit(code) }
}

/// libtorch's OpenMP (libgomp) lets idle worker threads spin by default, which is fastest on an
/// otherwise idle machine and ruinous on a shared one: with one other busy process on 2 cores a
/// roll-out step went from 34 ms to 510 ms (56 ms with passive waiting). libgomp reads
/// `OMP_WAIT_POLICY` while it loads, before `main`, so when the user has not chosen a policy we
/// run ourselves again with `PASSIVE` set (children, e.g. `batch`'s jobs, inherit it).
fn passive_openmp() {
    use std::os::unix::process::CommandExt;
    if std::env::var_os("OMP_WAIT_POLICY").is_some() {
        return;
    }
    let Ok(exe) = std::env::current_exe() else {
        return;
    };
    // `exec` returns only when it failed; then we carry on with libgomp's default.
    let _ = std::process::Command::new(exe)
        .args(std::env::args_os().skip(1))
        .env("OMP_WAIT_POLICY", "PASSIVE")
        .exec();
}
