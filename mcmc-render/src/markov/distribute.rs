//! The Markov-chain driver on a cluster ([`crate::cluster`]): every rank
//! builds the same tasks (same start-up, same chain streams), runs the
//! tasks [`crate::cluster::owns`] deals it, and sends each task's sums —
//! films, running normalisations, mutations, ratio sums, per-depth counts,
//! `normalization=filmed`'s sums — to rank 0, which adds them in task order exactly as one process does.
//! The image and the pooled normalisation `b` are therefore bit-identical
//! for any number of ranks. Chain and exchange statistics travel as JSON,
//! one report per rank, and are merged in rank order (their counters are
//! exact; the sums of acceptance probabilities may differ from a single
//! process in the last bits).

use super::estimator::{DepthAcceptance, FilmedSums, RatioSum, TransitionCounts};
use super::work::Task;
use super::{ChainFamily, ExchangePair, ExchangeSummary};
use crate::cluster::{Cluster, Parcel};
use crate::film::{Film, Filter};
use mcmc_core::startup::RunningNormalization;
use mcmc_core::stats::{ChainStatistics, ComponentStatistics};
use serde_json::{Value, json};
use std::borrow::Cow;
use std::sync::Arc;

/// What one task adds to the members' totals: borrowed from a local task
/// or rebuilt from a parcel another rank sent.
pub(crate) struct TaskSums<'a> {
    pub members: Cow<'a, [usize]>,
    pub films: Cow<'a, [Option<Film>]>,
    pub running: Cow<'a, [RunningNormalization]>,
    pub mutations: Cow<'a, [u64]>,
    pub ratios: Cow<'a, [RatioSum]>,
    /// [`super::Normalization::Filmed`]'s sums (empty under the others).
    pub filmed: Cow<'a, [FilmedSums]>,
    pub counts: Cow<'a, TransitionCounts>,
}

impl<'a> TaskSums<'a> {
    /// The sums of a local task.
    pub fn of<F: ChainFamily>(t: &'a Task<'_, F>) -> Self {
        TaskSums {
            members: Cow::Borrowed(&t.members),
            films: Cow::Borrowed(&t.films),
            running: Cow::Borrowed(&t.running),
            mutations: Cow::Borrowed(&t.mutations),
            ratios: Cow::Borrowed(&t.ratios),
            filmed: Cow::Borrowed(&t.filmed),
            counts: Cow::Borrowed(&t.counts),
        }
    }

    /// The parcel of task `unit` (counts: the member count, members,
    /// mutations, running counts, per-depth pairs, the NaN coordinates'
    /// length + 1 or 0, the sample-count image's length and width, then,
    /// under `normalization=filmed` only, the member count again and the
    /// filmed draws' counts; numbers: the running logs, the ratio sums,
    /// the NaN coordinates, the sample counts, then the filmed draws' logs
    /// and share sums). Without filmed sums a parcel has the words it had
    /// before they existed, so earlier checkpoints stay readable.
    pub(crate) fn parcel(&self, unit: usize) -> Parcel {
        let n = self.members.len();
        let mut counts = vec![n as u64];
        counts.extend(self.members.iter().map(|&m| m as u64));
        counts.extend(self.mutations.iter());
        let mut numbers = Vec::with_capacity(4 * n);
        for r in self.running.iter() {
            let (count, log_sum, log_sum_sq) = r.parts();
            counts.push(count);
            numbers.extend([log_sum, log_sum_sq]);
        }
        for r in self.ratios.iter() {
            numbers.extend([r.weight, r.sum]);
        }
        counts.push(self.counts.per_depth.len() as u64);
        for d in &self.counts.per_depth {
            counts.extend([d.proposed, d.accepted]);
        }
        match &self.counts.first_nonfinite {
            Some(coords) => {
                counts.push(coords.len() as u64 + 1);
                numbers.extend(coords);
            }
            None => counts.push(0),
        }
        counts.extend([
            self.counts.samples.len() as u64,
            u64::from(self.counts.width),
        ]);
        numbers.extend(self.counts.samples.iter().map(|&v| f64::from(v)));
        if !self.filmed.is_empty() {
            counts.push(self.filmed.len() as u64);
            for f in self.filmed.iter() {
                let (count, log_sum, log_sum_sq) = f.b.parts();
                counts.push(count);
                numbers.extend([log_sum, log_sum_sq, f.share.weight, f.share.sum]);
            }
        }
        Parcel {
            unit,
            films: self.films.to_vec(),
            numbers,
            counts,
        }
    }

    /// The sums a [`TaskSums::parcel`] carries, from another rank of the
    /// same binary (checked at start-up): a malformed parcel is a bug.
    pub(crate) fn from_parcel(p: Parcel) -> TaskSums<'static> {
        Self::try_from_parcel(p).expect("a task parcel from a rank of the same binary")
    }

    /// The sums a parcel carries, refused (one line) when its words do not
    /// have the shape [`TaskSums::parcel`] writes or a counter exceeds
    /// 2^53 (a forged checkpoint): every length is checked against the
    /// words left before anything of that length is allocated.
    pub(crate) fn try_from_parcel(p: Parcel) -> Result<TaskSums<'static>, String> {
        const MAX: u64 = crate::checkpoint::MAX_COUNT;
        let (n_counts, n_numbers) = (p.counts.len(), p.numbers.len());
        let mut c = p.counts.into_iter();
        let mut x = p.numbers.into_iter();
        let mut count = || c.next().ok_or("a task's sums are cut");
        // A length of `per` words each, within the `left` words there are.
        let length = |k: u64, per: usize, left: usize| {
            usize::try_from(k)
                .ok()
                .filter(|&k| k.saturating_mul(per) <= left)
                .ok_or_else(|| format!("a task's sums claim {k} entries"))
        };
        let counter = |k: u64| {
            if k <= MAX {
                Ok(k)
            } else {
                Err(format!("a task's counter {k} exceeds 2^53"))
            }
        };
        let n = length(count()?, 3, n_counts)?;
        let members = (0..n)
            .map(|_| usize::try_from(count()?).map_err(|_| "a member index overflows".to_string()))
            .collect::<Result<Vec<usize>, String>>()?;
        let mutations = (0..n)
            .map(|_| counter(count()?))
            .collect::<Result<Vec<u64>, String>>()?;
        let counts_of_running = (0..n)
            .map(|_| counter(count()?))
            .collect::<Result<Vec<u64>, String>>()?;
        let depths = length(count()?, 2, n_counts)?;
        let per_depth = (0..depths)
            .map(|_| {
                Ok(DepthAcceptance {
                    proposed: counter(count()?)?,
                    accepted: counter(count()?)?,
                })
            })
            .collect::<Result<_, String>>()?;
        let coords = length(count()?, 1, n_numbers + 1)?;
        let samples_len = length(count()?, 1, n_numbers)?;
        let width = u32::try_from(count()?).map_err(|_| "a sample image's width overflows")?;
        if samples_len > 0 && (width == 0 || samples_len % width as usize != 0) {
            return Err(format!(
                "{samples_len} sample counts do not make rows of {width}"
            ));
        }
        // Filmed sums are the parcel's last counts, when there are any.
        let counts_of_filmed = match count() {
            Err(_) => Vec::new(),
            Ok(k) if k == n as u64 => (0..n)
                .map(|_| counter(count()?))
                .collect::<Result<Vec<u64>, String>>()?,
            Ok(k) => return Err(format!("a task of {n} members has filmed sums of {k}")),
        };
        if c.next().is_some() {
            return Err("a task's sums have trailing words".into());
        }
        let mut number = || x.next().ok_or("a task's numbers are cut");
        let running = counts_of_running
            .iter()
            .map(|&k| Ok(RunningNormalization::from_parts((k, number()?, number()?))))
            .collect::<Result<_, String>>()?;
        let ratios = (0..n)
            .map(|_| {
                Ok(RatioSum {
                    weight: number()?,
                    sum: number()?,
                })
            })
            .collect::<Result<_, String>>()?;
        let first_nonfinite = match coords {
            0 => None,
            _ => Some((1..coords).map(|_| number()).collect::<Result<_, _>>()?),
        };
        // Counts are f32 sums: the f64 round trip is exact.
        let samples = (0..samples_len)
            .map(|_| number().map(|v| v as f32))
            .collect::<Result<_, _>>()?;
        let filmed = counts_of_filmed
            .iter()
            .map(|&k| {
                Ok(FilmedSums {
                    b: RunningNormalization::from_parts((k, number()?, number()?)),
                    share: RatioSum {
                        weight: number()?,
                        sum: number()?,
                    },
                })
            })
            .collect::<Result<_, String>>()?;
        if x.next().is_some() {
            return Err("a task's sums have trailing numbers".into());
        }
        Ok(TaskSums {
            members: Cow::Owned(members),
            films: Cow::Owned(p.films),
            running: Cow::Owned(running),
            mutations: Cow::Owned(mutations),
            ratios: Cow::Owned(ratios),
            filmed: Cow::Owned(filmed),
            counts: Cow::Owned(TransitionCounts {
                per_depth,
                first_nonfinite,
                samples,
                width,
            }),
        })
    }
}

/// Every task's sums on rank 0, in task order (`ids[i]` is local task
/// `i`'s index); `None` on the other ranks.
pub(crate) fn gather_tasks<F: ChainFamily>(
    cluster: &dyn Cluster,
    tasks: &[Task<'_, F>],
    ids: &[usize],
    filter: &Arc<Filter>,
) -> Option<Vec<TaskSums<'static>>> {
    let parcels = tasks
        .iter()
        .zip(ids)
        .map(|(t, &id)| TaskSums::of(t).parcel(id))
        .collect();
    let all = cluster.gather(parcels, filter)?;
    Some(all.into_iter().map(TaskSums::from_parcel).collect())
}

/// This rank's chain and exchange statistics and its share of the work,
/// as JSON (one entry of the sidecar's `"ranks"`).
pub(crate) fn rank_report(
    member_stats: &[Option<ChainStatistics>],
    exchange: &Option<ExchangeSummary>,
    tasks: usize,
    mutations: u64,
    seconds: f64,
) -> Value {
    let stats: Vec<Value> = member_stats
        .iter()
        .map(|s| match s {
            None => Value::Null,
            Some(s) => json!({
                "steps": s.steps, "accepted": s.accepted, "evaluations": s.evaluations,
                "invalid_density": s.invalid_density, "outside_support": s.outside_support,
                "failed": s.failed,
                "components": s.components.iter()
                    .map(|c| json!([c.name, c.proposed, c.accepted, c.sum_alpha]))
                    .collect::<Vec<_>>(),
            }),
        })
        .collect();
    json!({
        "tasks": tasks,
        "mutations": mutations,
        "seconds": seconds,
        "member_statistics": stats,
        "exchange": exchange,
    })
}

fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or(0)
}

/// Merges the ranks' reports ([`rank_report`]) in rank order into
/// per-member chain statistics and the exchange summary.
pub(crate) fn merge_reports(
    reports: &[Value],
    members: usize,
) -> (Vec<Option<ChainStatistics>>, Option<ExchangeSummary>) {
    let mut stats: Vec<Option<ChainStatistics>> = vec![None; members];
    let mut exchange: Option<ExchangeSummary> = None;
    for r in reports {
        for (m, s) in r["member_statistics"]
            .as_array()
            .into_iter()
            .flatten()
            .enumerate()
        {
            if s.is_null() || m >= members {
                continue;
            }
            let components = s["components"].as_array().into_iter().flatten();
            let cs = ChainStatistics {
                steps: u(&s["steps"]),
                accepted: u(&s["accepted"]),
                evaluations: u(&s["evaluations"]),
                invalid_density: u(&s["invalid_density"]),
                outside_support: u(&s["outside_support"]),
                failed: u(&s["failed"]),
                components: components
                    .map(|c| ComponentStatistics {
                        name: c[0].as_str().unwrap_or_default().to_string(),
                        proposed: u(&c[1]),
                        accepted: u(&c[2]),
                        sum_alpha: c[3].as_f64().unwrap_or(f64::NAN),
                    })
                    .collect(),
            };
            match stats[m].as_mut() {
                Some(old) => old.merge(&cs),
                None => stats[m] = Some(cs),
            }
        }
        let e = &r["exchange"];
        if e.is_object() {
            let summary = exchange.get_or_insert_with(|| {
                ExchangeSummary::new(e["name"].as_str().unwrap_or_default().into())
            });
            summary.sweeps += u(&e["sweeps"]);
            summary.round_trips += u(&e["round_trips"]);
            for p in e["pairs"].as_array().into_iter().flatten() {
                let attempted = u(&p["attempted"]);
                summary.add_pair(ExchangePair {
                    i: u(&p["i"]) as usize,
                    j: u(&p["j"]) as usize,
                    attempted,
                    accepted: u(&p["accepted"]),
                    mean_alpha: p["mean_alpha"].as_f64().unwrap_or(f64::NAN),
                });
            }
        }
    }
    (stats, exchange)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::FilterKind;

    #[test]
    fn task_sums_round_trip_through_a_parcel_bit_exactly() {
        let filter = Arc::new(Filter::new(FilterKind::Box, 3, 2));
        let mut film = Film::new(3, 2, filter.clone());
        film.add_sample(
            glam::Vec2::new(0.5, 0.5),
            crate::color::Rgb::new(0.3, 0.0, 1e-40),
        );
        let mut running = RunningNormalization::new();
        running.add(-1.25);
        running.add(f64::NEG_INFINITY);
        let sums = TaskSums {
            members: Cow::Owned(vec![2, 3]),
            films: Cow::Owned(vec![Some(film.clone()), None]),
            running: Cow::Owned(vec![running.clone(), RunningNormalization::new()]),
            mutations: Cow::Owned(vec![7, 0]),
            ratios: Cow::Owned(vec![
                RatioSum {
                    weight: 0.5,
                    sum: 0.1,
                },
                RatioSum::default(),
            ]),
            filmed: Cow::Owned(Vec::new()),
            counts: Cow::Owned(TransitionCounts {
                per_depth: vec![DepthAcceptance {
                    proposed: 4,
                    accepted: 1,
                }],
                first_nonfinite: Some(vec![0.25, f64::MIN_POSITIVE]),
                samples: vec![0.75, 0.0, 1e-30],
                width: 3,
            }),
        };
        // Without filmed sums the parcel ends as before they existed (the
        // sample image's width is its last count).
        assert_eq!(sums.parcel(9).counts.last(), Some(&3));
        let back = TaskSums::from_parcel(sums.parcel(9));
        assert!(back.filmed.is_empty());
        assert_eq!(&*back.members, &[2, 3]);
        assert_eq!(&*back.mutations, &[7, 0]);
        let bits = |r: &RunningNormalization| {
            let (c, a, b) = r.parts();
            (c, a.to_bits(), b.to_bits())
        };
        assert_eq!(bits(&back.running[0]), bits(&running));
        assert_eq!(bits(&back.running[1]), bits(&RunningNormalization::new()));
        assert_eq!((back.ratios[0].weight, back.ratios[0].sum), (0.5, 0.1));
        assert_eq!(
            back.counts.per_depth,
            vec![DepthAcceptance {
                proposed: 4,
                accepted: 1
            }]
        );
        assert_eq!(
            back.counts.first_nonfinite,
            Some(vec![0.25, f64::MIN_POSITIVE])
        );
        assert_eq!(back.counts.samples, vec![0.75, 0.0, 1e-30]);
        assert_eq!(back.counts.width, 3);
        assert!(back.films[1].is_none());
        assert_eq!(
            back.films[0].as_ref().unwrap().accumulators().0,
            film.accumulators().0
        );
        let mut filmed = FilmedSums::default();
        filmed.add_draw(-0.75);
        filmed.add_draw(f64::NEG_INFINITY);
        filmed.add_state(0.25, -0.5);
        let with_filmed = TaskSums {
            filmed: Cow::Owned(vec![FilmedSums::default(), filmed.clone()]),
            ..sums
        };
        let back = TaskSums::from_parcel(with_filmed.parcel(9));
        assert_eq!(back.filmed.len(), 2);
        assert_eq!(bits(&back.filmed[1].b), bits(&filmed.b));
        assert_eq!(bits(&back.filmed[0].b), bits(&RunningNormalization::new()));
        let share = |f: &FilmedSums| (f.share.weight.to_bits(), f.share.sum.to_bits());
        assert_eq!(share(&back.filmed[1]), share(&filmed));
        assert_eq!(bits(&back.running[0]), bits(&running));
        assert_eq!(back.counts.samples, vec![0.75, 0.0, 1e-30]);
    }

    #[test]
    fn rank_reports_merge_into_summed_counters() {
        let mut cs = ChainStatistics::new(vec!["small".into()]);
        cs.steps = 10;
        cs.accepted = 4;
        cs.components[0].proposed = 10;
        cs.components[0].accepted = 4;
        cs.components[0].sum_alpha = 4.5;
        let a = rank_report(&[Some(cs.clone()), None], &None, 2, 10, 1.0);
        let b = rank_report(&[Some(cs), None], &None, 1, 10, 1.0);
        let (stats, exchange) = merge_reports(&[a, b], 2);
        let s = stats[0].as_ref().unwrap();
        assert_eq!((s.steps, s.accepted, s.components[0].proposed), (20, 8, 20));
        assert_eq!(s.components[0].sum_alpha, 9.0);
        assert!(stats[1].is_none() && exchange.is_none());
    }

    /// A path sampler that counts its traces (every evaluation of a state)
    /// and splats one unit of light.
    struct Counting<'a>(&'a std::sync::atomic::AtomicUsize);

    impl crate::pss::PssPathSampler for Counting<'_> {
        fn streams(&self) -> usize {
            1
        }
        fn trace(
            &self,
            scene: &crate::scene::Scene,
            source: &mut crate::pss::PssSource<'_>,
            out: &mut Vec<crate::pss::Splat>,
        ) -> u32 {
            self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let p = crate::pss::raster_of(scene, source);
            out.push(crate::pss::Splat {
                p,
                l: crate::color::Rgb::new(1.0, 1.0, 1.0),
                class: 0,
            });
            1
        }
    }

    #[test]
    fn a_rank_builds_and_evaluates_only_the_chains_of_its_tasks() {
        use crate::integrators::RunSettings;
        use crate::markov::work::Units;
        use crate::markov::{ChainParams, chain_tasks};
        use std::sync::atomic::{AtomicUsize, Ordering};
        let text = r#"<scene version="3.0.0">
            <sensor type="perspective"><film type="hdrfilm">
                <integer name="width" value="4"/><integer name="height" value="4"/>
            </film></sensor>
            <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
        </scene>"#;
        let path = std::path::Path::new("s.xml");
        let scene = crate::scene::Scene::load_str(text, path, std::path::Path::new("."))
            .expect("test scene");
        let traces = AtomicUsize::new(0);
        let family = crate::pss::PssFamily::new(&scene, vec![Counting(&traces)]);
        let mutation = crate::pss::MutationParams::default().mutation().unwrap();
        let params = ChainParams {
            chains: 37,
            ..ChainParams::default()
        };
        let settings = params.chain_settings(mutation, &RunSettings::default());
        let starts = vec![(0..37).map(|i| family.candidate(3, i)).collect::<Vec<_>>()];
        let filter = Arc::new(Filter::new(FilterKind::Box, 4, 4));
        let film = || Film::new(4, 4, filter.clone());
        let build = |owned: &dyn Fn(usize) -> bool| {
            let tasks = chain_tasks(&family, &settings, &starts, Some(5000), &film, owned);
            (tasks.unwrap(), traces.swap(0, Ordering::SeqCst))
        };
        // What a chain is at the start: its density, stream and budget.
        let chains = |task: &Task<'_, _>| -> Vec<(u64, [u64; 4], Option<u64>)> {
            let Units::Chains(c) = &task.units else {
                unreachable!("chain tasks")
            };
            c.iter()
                .map(|s| {
                    let rng = mcmc_core::rng::rng_words(s.chain.rng());
                    (s.chain.current().log_density.to_bits(), rng, s.remaining)
                })
                .collect()
        };
        let (whole, whole_traces) = build(&|_| true);
        assert_eq!(whole_traces, 37, "one evaluation per chain start");
        for size in 1..5 {
            let mut traced = 0;
            for rank in 0..size {
                let (tasks, n) = build(&|t| t % size == rank);
                traced += n;
                assert_eq!(tasks.len(), whole.len());
                for (t, (task, one)) in tasks.iter().zip(&whole).enumerate() {
                    let want = if t % size == rank {
                        chains(one)
                    } else {
                        Vec::new()
                    };
                    assert_eq!(chains(task), want, "task {t} on rank {rank} of {size}");
                }
            }
            // Each start once over all ranks (building every task on
            // every rank, as before, traced `size` times as many).
            assert_eq!(traced, whole_traces, "{size} ranks");
        }
    }
}
