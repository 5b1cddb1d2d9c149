//! Independent benchmark work spread over the machine's cores.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Runs `work` on every item, as many at once as the machine has cores, and returns the
/// outcomes in the order of `items`. For work whose figures do not depend on what runs
/// beside it: each object's learning has its own simulator, each planner's episodes their
/// own freshly seeded pipeline (a lockstep ring keeps about one core busy), so running them
/// side by side changes the wall time only. A panic in `work` is raised again here.
pub fn side_by_side<I: Sync, T: Send>(items: &[I], work: impl Fn(&I) -> T + Sync) -> Vec<T> {
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len())
        .max(1);
    let next = AtomicUsize::new(0);
    let mut done: Vec<(usize, T)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(item) = items.get(i) else { break };
                        mine.push((i, work(item)));
                    }
                    mine
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, outcome)| outcome).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_is_worked_once_and_the_outcomes_keep_the_items_order() {
        let items: Vec<u64> = (0..37).collect();
        let calls = AtomicUsize::new(0);
        let out = side_by_side(&items, |&x| {
            calls.fetch_add(1, Ordering::Relaxed);
            x * x
        });
        assert_eq!(calls.load(Ordering::Relaxed), items.len());
        assert_eq!(out, items.iter().map(|x| x * x).collect::<Vec<_>>());
    }

    #[test]
    fn no_items_give_no_outcomes() {
        let out: Vec<u8> = side_by_side(&[] as &[u8], |&x| x);
        assert!(out.is_empty());
    }
}
