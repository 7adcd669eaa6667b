fn main() -> std::process::ExitCode {
    translucent::cli::main()
}
