//! The `mcmc-render` command line; see [`mcmc_render::cli`].

fn main() {
    mcmc_render::cli::main();
}
