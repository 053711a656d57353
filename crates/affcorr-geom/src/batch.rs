//! The rayon policy shared by every batched function.
//!
//! Below [`PARALLEL_MIN_LEN`] rows the work is done on the calling thread: for the per-row costs
//! here (tens of nanoseconds) rayon's fork-join overhead only pays off on a few thousand rows.

use rayon::prelude::*;

/// Batches shorter than this run on the calling thread.
pub const PARALLEL_MIN_LEN: usize = 4096;
/// Rows handed to one rayon task: large enough to amortise scheduling.
const CHUNK: usize = 1024;

/// `out[i] = f(i)` for every i, in parallel for large batches. If `f` fails for some rows, the
/// error of the smallest failing index is returned (deterministic whatever the thread count);
/// `out` is then partially written.
pub fn try_fill<T, E, F>(out: &mut [T], f: F) -> Result<(), E>
where
    T: Send,
    E: Send,
    F: Fn(usize) -> Result<T, E> + Sync,
{
    if out.len() < PARALLEL_MIN_LEN {
        for (i, o) in out.iter_mut().enumerate() {
            *o = f(i)?;
        }
        return Ok(());
    }
    // Each chunk reports its first failure; the smallest chunk index wins.
    let first_error = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .filter_map(|(c, chunk)| {
            for (k, o) in chunk.iter_mut().enumerate() {
                match f(c * CHUNK + k) {
                    Ok(v) => *o = v,
                    Err(e) => return Some((c, e)),
                }
            }
            None
        })
        .min_by_key(|(c, _)| *c);
    match first_error {
        Some((_, e)) => Err(e),
        None => Ok(()),
    }
}

/// `out[i] = f(i)` for infallible `f`, in parallel for large batches.
pub fn fill<T, F>(out: &mut [T], f: F)
where
    T: Send,
    F: Fn(usize) -> T + Sync,
{
    let _ = try_fill::<T, std::convert::Infallible, _>(out, |i| Ok(f(i)));
}

/// [`try_fill`] for three outputs (struct of arrays): `(a[i], b[i], c[i]) = f(i)`, with
/// the same threshold, chunking and smallest-failing-index error. The `*_columns` forms use it to
/// write straight into the caller's (e.g. numpy's) arrays, with no intermediate rows.
pub(crate) fn try_fill3<A, B, C, E, F>(a: &mut [A], b: &mut [B], c: &mut [C], f: F) -> Result<(), E>
where
    A: Send,
    B: Send,
    C: Send,
    E: Send,
    F: Fn(usize) -> Result<(A, B, C), E> + Sync,
{
    debug_assert!(a.len() == b.len() && a.len() == c.len());
    if a.len() < PARALLEL_MIN_LEN {
        for (i, ((x, y), z)) in a.iter_mut().zip(b.iter_mut()).zip(c.iter_mut()).enumerate() {
            (*x, *y, *z) = f(i)?;
        }
        return Ok(());
    }
    let first_error = a
        .par_chunks_mut(CHUNK)
        .zip(b.par_chunks_mut(CHUNK))
        .zip(c.par_chunks_mut(CHUNK))
        .enumerate()
        .filter_map(|(chunk, ((ca, cb), cc))| {
            let rows = ca.iter_mut().zip(cb.iter_mut()).zip(cc.iter_mut());
            for (k, ((x, y), z)) in rows.enumerate() {
                match f(chunk * CHUNK + k) {
                    Ok(v) => (*x, *y, *z) = v,
                    Err(e) => return Some((chunk, e)),
                }
            }
            None
        })
        .min_by_key(|(chunk, _)| *chunk);
    first_error.map_or(Ok(()), |(_, e)| Err(e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_matches_sequential_on_both_sides_of_threshold() {
        for n in [
            0,
            1,
            PARALLEL_MIN_LEN - 1,
            PARALLEL_MIN_LEN,
            3 * PARALLEL_MIN_LEN + 17,
        ] {
            let mut out = vec![0usize; n];
            fill(&mut out, |i| i * i);
            assert!(out.iter().enumerate().all(|(i, &v)| v == i * i), "n = {n}");
        }
    }

    #[test]
    fn try_fill_reports_smallest_failing_index() {
        let n = 5 * PARALLEL_MIN_LEN;
        let mut out = vec![0usize; n];
        let bad = [n - 3, 2 * PARALLEL_MIN_LEN + 5, PARALLEL_MIN_LEN + 1];
        let r = try_fill(&mut out, |i| if bad.contains(&i) { Err(i) } else { Ok(i) });
        assert_eq!(r, Err(PARALLEL_MIN_LEN + 1));
        let mut small = vec![0usize; 10];
        assert_eq!(
            try_fill(&mut small, |i| if i >= 4 { Err(i) } else { Ok(i) }),
            Err(4)
        );
    }
}
