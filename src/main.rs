fn main() {
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
