//! The thin layer that runs fits on several threads.
//!
//! This is the one part of `fit` that uses threads (`std::thread::scope`,
//! nothing that outlives a call). It only distributes work whose results do
//! not depend on where or in what order it runs: the candidates of one
//! search generation (Monte Carlo objective only; closed forms are cheaper
//! than a thread), the replicas of one confirmation round, and the entries
//! of a database. Every result is therefore the same for any thread count.

use super::confirm::Replica;
use super::{
    assemble, conclude, family_of, jitter_searched, search, search_config, Confirmation, FitError, FitRequest, FitResult, Kind,
    Objective, Searched,
};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Where a fit is, for progress bars.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// A search generation finished.
    Search { generation: usize, max_generations: usize, objective: f64 },
    /// A confirmation round finished.
    Confirm { batches: usize, max_batches: usize, frames: u64 },
}

/// Fits one request using up to `threads` threads.
pub fn fit(req: &FitRequest, threads: usize, progress: &(dyn Fn(Progress) + Sync)) -> Result<FitResult, FitError> {
    let searched = if req.kind == Kind::Jitter { jitter_searched(req)? } else { searched(req, threads, progress)? };
    let metrics: Vec<_> = req.goals.iter().map(|g| g.metric).collect();
    let mut confirmation = Confirmation::new(&searched.spec, &metrics, req.confirm_seed(), req.frame_interval_ns())?;
    while !confirmation.done() {
        run_round(&mut confirmation, threads);
        let (batches, max_batches) = confirmation.batches_done();
        progress(Progress::Confirm { batches, max_batches, frames: confirmation.frames() });
    }
    Ok(assemble(req, searched, &confirmation))
}

/// The search of a family, and its conclusion.
fn searched(req: &FitRequest, threads: usize, progress: &(dyn Fn(Progress) + Sync)) -> Result<Searched, FitError> {
    let family = family_of(req)?;
    let crn_seed = req.crn_seed();
    let parallel = threads > 1 && req.objective == Objective::MonteCarlo;
    let max_generations = search_config(req).max_generations;
    let result = {
        let family = &family;
        let goals = &req.goals;
        let objective = req.objective;
        let mut evaluate = |xs: &[Vec<f64>]| -> Vec<f64> {
            let f = |x: &Vec<f64>| family.objective(x, goals, objective, crn_seed);
            if parallel {
                par_map(xs, threads, f)
            } else {
                xs.iter().map(f).collect()
            }
        };
        search(req, family, &mut evaluate, &mut |generation, objective| {
            progress(Progress::Search { generation, max_generations, objective })
        })
    };
    conclude(req, family, &result)
}

/// Fits every request, each on one thread, `threads` at a time; results in
/// the order of `requests`. `done(index, result)` is called as each finishes.
pub fn fit_many(
    requests: &[FitRequest],
    threads: usize,
    done: &(dyn Fn(usize, &Result<FitResult, FitError>) + Sync),
) -> Vec<Result<FitResult, FitError>> {
    let next = AtomicUsize::new(0);
    let slots: Mutex<Vec<Option<Result<FitResult, FitError>>>> = Mutex::new(vec![None; requests.len()]);
    let work = || loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        let Some(req) = requests.get(i) else { break };
        let r = fit(req, 1, &|_| {});
        done(i, &r);
        slots.lock().expect("no worker panics while holding the lock")[i] = Some(r);
    };
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(work);
        }
    });
    slots.into_inner().expect("workers finished").into_iter().map(|r| r.expect("every request ran")).collect()
}

/// One confirmation round, its replicas spread over `threads` threads.
pub fn run_round(confirmation: &mut Confirmation, threads: usize) {
    let replicas = confirmation.replicas_mut();
    if threads <= 1 {
        replicas.iter_mut().for_each(Replica::run_round);
        return;
    }
    let per = replicas.len().div_ceil(threads);
    std::thread::scope(|s| {
        for part in replicas.chunks_mut(per) {
            s.spawn(move || part.iter_mut().for_each(Replica::run_round));
        }
    });
}

/// `f` over `items` on up to `threads` threads, results in order.
pub fn par_map<T: Sync, R: Send>(items: &[T], threads: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    if threads <= 1 || items.len() < 2 {
        return items.iter().map(f).collect();
    }
    let per = items.len().div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> =
            items.chunks(per).map(|part| s.spawn(move || part.iter().map(f).collect::<Vec<R>>())).collect();
        handles.into_iter().flat_map(|h| h.join().expect("a worker panicked")).collect()
    })
}
