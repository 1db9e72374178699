//! Data parallelism where it pays (the dig model over candidate starts, the cross-validation folds):
//! rayon with the crate's `parallel` feature, a plain loop without it, so the real-time core can build
//! the planner without a thread pool. The results are the same either way, in input order.

/// `f` over `0..n`, the results in index order.
pub(crate) fn map_indices<R: Send>(n: usize, f: impl Fn(usize) -> R + Sync + Send) -> Vec<R> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        (0..n).map(f).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_keep_the_index_order() {
        assert_eq!(
            map_indices(1000, |i| i * i),
            (0..1000).map(|i| i * i).collect::<Vec<_>>()
        );
        assert!(map_indices(0, |i| i).is_empty());
    }
}
