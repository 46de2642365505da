//! Samples a Gaussian mixture described in JSON; see `mcmc_examples::mixture`
//! for the flags, the file format and the output.

fn main() {
    match mcmc_examples::mixture::run_cli(std::env::args_os()) {
        Ok(out) => print!("{out}"),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(e.code);
        }
    }
}
