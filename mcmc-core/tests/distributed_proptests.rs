//! Property tests for [`DistributedReplicaExchange`] (feature `mpi`; issue
//! #23, "the core too"): its constructor with arbitrary inputs, and
//! `resume` with arbitrary and with damaged checkpoint files, must give
//! `Ok` or an error — never a panic, a hang or a silently wrong run.
//!
//! MPI is initialised once per process, so this is a test without the
//! libtest harness (`harness = false`): `main` initialises MPI and runs
//! each property with proptest's runner on a fixed seed. Run it in one
//! process (an MPI singleton) or on several ranks, where every rank draws
//! the same inputs and every collective error must reach all of them
//! (a rank that panicked or refused alone would leave the others waiting:
//! `.ci/run` bounds the run with a timeout):
//!
//! ```sh
//! cargo test -p mcmc-core --features mpi --test distributed_proptests
//! mpirun -n 3 --oversubscribe target/debug/deps/distributed_proptests-<hash>
//! ```

use mcmc_core::distributed::mpi::topology::{Communicator, SimpleCommunicator};
use mcmc_core::distributed::{
    DistributedReplicaExchange, DistributedSchedule, FNV_OFFSET, Traffic, broadcast_bytes, fnv1a,
    mpi,
};
use mcmc_core::kernel::GaussianRandomWalk;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::{PowerFamily, ReplicaFamily, Tempered};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestError, TestRng, TestRunner};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

type Target = fn(&[f64]) -> f64;
type Family = PowerFamily<Target>;
type Alg = MetropolisHastings<GaussianRandomWalk, Vec<f64>, Tempered<()>>;
type Ensemble = DistributedReplicaExchange<Vec<f64>, Family, Alg>;

/// Two modes in 2-d; NaN coordinates give NaN, far ones −∞ after the
/// exponentials underflow, so arbitrary starts reach every density class.
fn two_modes(x: &[f64]) -> f64 {
    let d = |m: f64| -((x[0] - m).powi(2) + (x[1] - m).powi(2)) / 0.18;
    mcmc_core::math::log_sum_exp(&[d(-2.0), d(2.0)])
}

/// Inverse temperatures: mostly a valid ladder (1 first, non-increasing,
/// in [0, 1]) so that the constructor is reached, sometimes anything.
fn betas() -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        3 => proptest::collection::vec(0.0..=1.0f64, 0..7).prop_map(|mut rest| {
            rest.sort_by(|a, b| b.total_cmp(a));
            let mut b = vec![1.0];
            b.extend(rest);
            b
        }),
        1 => proptest::collection::vec(proptest::num::f64::ANY, 0..5),
    ]
}

/// A coordinate: mostly ordinary, sometimes any `f64`.
fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![3 => -5.0..5.0f64, 1 => proptest::num::f64::ANY]
}

/// Everything the constructor takes, each part free to be wrong.
#[derive(Clone, Debug)]
struct Inputs {
    betas: Vec<f64>,
    initial: Vec<Vec<f64>>,
    scales: Vec<f64>,
    neighbour: bool,
    seed: u64,
    fingerprint: u64,
}

/// A count that is mostly right for `levels` (as `right` says) and
/// sometimes anything, so that both the accepted and the refused paths run.
fn count(right: Vec<usize>) -> impl Strategy<Value = usize> {
    prop_oneof![3 => proptest::sample::select(right), 1 => 0usize..9]
}

fn inputs() -> impl Strategy<Value = Inputs> {
    betas()
        .prop_flat_map(|betas| {
            let n = betas.len();
            (count(vec![1, n]), count(vec![n])).prop_flat_map(move |(starts, kernels)| {
                (
                    Just(betas.clone()),
                    proptest::collection::vec(proptest::collection::vec(coordinate(), 2), starts),
                    proptest::collection::vec(
                        prop_oneof![3 => 0.05..3.0f64, 1 => proptest::num::f64::ANY],
                        kernels,
                    ),
                    any::<bool>(),
                    any::<u64>(),
                    any::<u64>(),
                )
            })
        })
        .prop_map(
            |(betas, initial, scales, neighbour, seed, fingerprint)| Inputs {
                betas,
                initial,
                scales,
                neighbour,
                seed,
                fingerprint,
            },
        )
}

/// The ensemble for `inputs`, or `None` where an input is refused before
/// the distributed constructor (the family's or a kernel's own check;
/// `constructor_proptests.rs` drives those).
fn build(world: &SimpleCommunicator, inputs: &Inputs) -> Option<Result<Ensemble, String>> {
    let family = PowerFamily::without_prior(two_modes as Target, inputs.betas.clone()).ok()?;
    let algorithms = inputs
        .scales
        .iter()
        .map(|&s| GaussianRandomWalk::isotropic(s).map(MetropolisHastings::new))
        .collect::<Result<Vec<Alg>, _>>()
        .ok()?;
    let schedule = if inputs.neighbour {
        DistributedSchedule::Neighbour
    } else {
        DistributedSchedule::EvenOdd
    };
    Some(
        DistributedReplicaExchange::new(
            world,
            family,
            inputs.initial.clone(),
            algorithms,
            schedule,
            inputs.seed,
            inputs.fingerprint,
        )
        .map_err(|e| e.to_string()),
    )
}

/// The inverse temperatures of [`valid`]'s ensembles.
fn valid_betas(levels: usize) -> Vec<f64> {
    (0..levels).map(|l| 0.5f64.powi(l as i32)).collect()
}

/// The family of [`valid`]'s ensembles.
fn valid_family(levels: usize) -> Family {
    PowerFamily::without_prior(two_modes as Target, valid_betas(levels)).expect("a valid ladder")
}

/// A valid ensemble of `levels` levels (for the `resume` properties).
fn valid(world: &SimpleCommunicator, levels: usize, neighbour: bool) -> Ensemble {
    let inputs = Inputs {
        betas: valid_betas(levels),
        initial: vec![vec![0.5, -0.25]],
        scales: vec![0.4; levels],
        neighbour,
        seed: 7,
        fingerprint: 11,
    };
    build(world, &inputs)
        .expect("valid family and kernels")
        .expect("a valid set-up")
}

/// Every level's `(state, ln π, replica)` on rank 0 (`None` elsewhere).
fn levels_of(e: &mut Ensemble) -> Option<Vec<(Vec<f64>, u64, usize)>> {
    e.gather_levels().map(|v| {
        v.into_iter()
            .map(|(s, r)| (s.state, s.log_density.to_bits(), r))
            .collect()
    })
}

/// A path for this process's checkpoint (only rank 0 reads or writes it).
fn scratch(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "mcmc-distributed-proptest-{}-{name}",
        std::process::id()
    ))
}

/// Writes `bytes` to `path` on rank 0 (the only rank that reads it).
fn put(world: &SimpleCommunicator, path: &Path, bytes: &[u8]) {
    if world.rank() == 0 {
        std::fs::write(path, bytes).expect("write a scratch file");
    }
}

/// Constructor: arbitrary levels, starts (NaN, ±∞, too many, too few),
/// kernels (too many, too few), schedules, seeds and fingerprints. An
/// accepted set-up must run, checkpoint and resume bit-identically.
fn constructor(world: &SimpleCommunicator, runner: &mut TestRunner) -> Result<(), String> {
    let path = scratch("constructor");
    let ran = Cell::new(0);
    let result = runner.run(&inputs(), |inputs| {
        guard(world, || {
            let Some(built) = build(world, &inputs) else {
                return Ok(());
            };
            let Ok(mut a) = built else {
                return Ok(());
            };
            ran.set(ran.get() + 1);
            let levels = inputs.betas.len();
            prop_assert_eq!(a.levels(), levels);
            prop_assert!(inputs.initial.len() == levels || inputs.initial.len() == 1);
            prop_assert_eq!(inputs.scales.len(), levels);
            // 0–4 sweeps before the checkpoint: both parities, and none.
            for _ in 0..inputs.seed % 5 {
                a.sweep();
            }
            a.checkpoint(&path)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            let mut b = build(world, &inputs)
                .expect("built once")
                .map_err(TestCaseError::fail)?;
            prop_assert_eq!(b.resume(&path), Ok(true));
            // Both ensembles live and interleaved: their messages must not
            // mix, and nothing may be left unreceived when one is dropped.
            for _ in 0..2 {
                a.sweep();
                b.sweep();
            }
            prop_assert_eq!(levels_of(&mut a), levels_of(&mut b));
            Ok(())
        })
    });
    let _ = std::fs::remove_file(&path);
    if world.rank() == 0 {
        println!(
            "constructor: {} set-ups accepted, run and resumed",
            ran.get()
        );
    }
    report("constructor", result)
}

/// `resume` from a file of arbitrary bytes: an error on every rank.
fn arbitrary_files(world: &SimpleCommunicator, runner: &mut TestRunner) -> Result<(), String> {
    let path = scratch("arbitrary");
    let magic = b"mcmcRE02".to_vec();
    let bytes = prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..600),
        // The right magic first, so the checks after it are reached.
        proptest::collection::vec(any::<u8>(), 0..600).prop_map(move |tail| {
            let mut b = magic.clone();
            b.extend(tail);
            b
        }),
    ];
    let result = runner.run(&bytes, |bytes| {
        guard(world, || {
            put(world, &path, &bytes);
            let mut e = valid(world, 4, false);
            prop_assert!(e.resume(&path).is_err());
            Ok(())
        })
    });
    let _ = std::fs::remove_file(&path);
    report("arbitrary checkpoint bytes", result)
}

/// A genuine checkpoint with one byte or one 8-byte word overwritten:
/// refused (the checksum). With the checksum recomputed over the change
/// (a forged file): refused, or continued to a run whose every level has
/// a finite density — never a panic, and never a replay of the exchange
/// stream sized by a forged count (that hung the earlier format).
fn damaged_files(world: &SimpleCommunicator, runner: &mut TestRunner) -> Result<(), String> {
    let path = scratch("damaged");
    let mut source = valid(world, 5, false);
    for _ in 0..20 {
        source.sweep();
    }
    source.checkpoint(&path).map_err(|e| e.to_string())?;
    // The same bytes on every rank, so that all draw the same cases.
    let mut genuine = Vec::new();
    if world.rank() == 0 {
        genuine = std::fs::read(&path).map_err(|e| e.to_string())?;
    }
    let genuine = broadcast_bytes(world, &mut Traffic::default(), &genuine);
    let body = genuine.len() - 8;
    let damage = (
        0..body,
        any::<u64>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
    );
    let (refused, continued) = (Cell::new(0), Cell::new(0));
    let result = runner.run(&damage, |(at, value, whole_word, forged, neighbour)| {
        guard(world, || {
            let mut bytes = genuine.clone();
            if whole_word {
                let at = (at / 8) * 8;
                bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
            } else {
                bytes[at] = value as u8;
            }
            if bytes == genuine {
                return Ok(());
            }
            if forged {
                let sum = fnv1a(&bytes[..body], FNV_OFFSET);
                bytes[body..].copy_from_slice(&sum.to_le_bytes());
            }
            put(world, &path, &bytes);
            let mut e = valid(world, 5, neighbour);
            match e.resume(&path) {
                Err(_) => refused.set(refused.get() + 1),
                Ok(resumed) => {
                    continued.set(continued.get() + 1);
                    prop_assert!(forged, "a damaged checkpoint was continued");
                    prop_assert!(resumed);
                    consistent(&mut e)?;
                    for _ in 0..3 {
                        e.sweep();
                    }
                    consistent(&mut e)?;
                }
            }
            Ok(())
        })
    });
    let _ = std::fs::remove_file(&path);
    if world.rank() == 0 {
        println!(
            "damaged checkpoints: {} refused, {} (forged) continued",
            refused.get(),
            continued.get()
        );
    }
    report("damaged checkpoints", result)
}

/// Every level's recorded `ln π` is its state's, within the tolerance the
/// library allows, and finite (a chain never holds an impossible state).
fn consistent(e: &mut Ensemble) -> Result<(), TestCaseError> {
    let Some(levels) = levels_of(e) else {
        return Ok(());
    };
    let family = valid_family(levels.len());
    for (level, (state, bits, _)) in levels.iter().enumerate() {
        let (recorded, now) = (
            f64::from_bits(*bits),
            family.evaluate(level, state).log_density,
        );
        prop_assert!(
            recorded.is_finite() && (recorded - now).abs() <= 1e-9 * (1.0 + now.abs()),
            "level {level} holds {state:?} with ln π {recorded}, which evaluates to {now}"
        );
    }
    Ok(())
}

/// Runs one case. A panic aborts the process with its message (proptest
/// would catch it silently and go on shrinking alone on this rank, while
/// the other ranks wait in a collective: a hang, not a failure). On
/// several ranks a failed assertion aborts too, for the same reason; in
/// one process it is returned, so proptest shrinks it.
fn guard(
    world: &SimpleCommunicator,
    case: impl FnOnce() -> Result<(), TestCaseError>,
) -> Result<(), TestCaseError> {
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(case));
    let failure = match &result {
        Ok(Ok(())) => return Ok(()),
        Ok(Err(e)) if world.size() == 1 => return Err(e.clone()),
        Ok(Err(e)) => e.to_string(),
        Err(payload) => payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into()),
    };
    eprintln!("rank {}: {failure}", world.rank());
    std::process::abort()
}

/// One property: runs its cases with the runner, on every rank.
type Property = fn(&SimpleCommunicator, &mut TestRunner) -> Result<(), String>;

/// A property's outcome as one line naming it.
fn report<T: std::fmt::Debug>(name: &str, result: Result<(), TestError<T>>) -> Result<(), String> {
    result.map_err(|e| format!("{name}: {e}"))
}

fn main() -> ExitCode {
    let Some(universe) = mpi::initialize() else {
        eprintln!("MPI could not be initialised");
        return ExitCode::FAILURE;
    };
    let world = universe.world();
    let properties: [(&str, u32, Property); 3] = [
        ("constructor", 256, constructor),
        ("arbitrary checkpoint bytes", 256, arbitrary_files),
        ("damaged checkpoints", 256, damaged_files),
    ];
    let mut failed = false;
    for (name, cases, property) in properties {
        // A fixed seed: every rank draws the same inputs, and CI is
        // deterministic; no failure persistence (one process per rank).
        let config = Config {
            cases,
            failure_persistence: None,
            ..Config::default()
        };
        let mut runner = TestRunner::new_with_rng(
            config,
            TestRng::from_seed(RngAlgorithm::ChaCha, &[23u8; 32]),
        );
        match property(&world, &mut runner) {
            Ok(()) => {
                if world.rank() == 0 {
                    println!("{name}: {cases} cases passed on {} ranks", world.size());
                }
            }
            Err(e) => {
                eprintln!("rank {}: {e}", world.rank());
                failed = true;
            }
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
