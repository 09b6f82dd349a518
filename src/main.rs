fn main() {
    std::process::exit(garmentbake::cli::main());
}
