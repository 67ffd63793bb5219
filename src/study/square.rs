//! Balanced Latin squares (Williams designs) for counterbalancing the order
//! of a study's blocks.
//!
//! A square for `n` blocks is a list of rows, each an order of `0..n`, such
//! that across all its rows every block stands in every position equally
//! often and every block directly follows every other equally often (first
//! order carry-over balance). For even `n` one square of `n` rows does both;
//! for odd `n` no square of `n` rows can, and the design is the square
//! followed by its mirror image, `2n` rows (Williams, 1949). One block is
//! one row.
//!
//! Pure: no clock, file or randomness; participants take the rows in turn.

/// The most blocks a study may have: far beyond any within-subject study,
/// and small enough that a square (at most 2·64 rows of 64) costs nothing.
pub const MAX_BLOCKS: usize = 64;

/// The rows of the balanced Latin square for `n` blocks (`n` rows for even
/// `n`, `2n` for odd `n` > 1), each an order of `0..n`. The square of four
/// is the textbook ABDC, BCAD, CDBA, DACB.
///
/// # Panics
/// If `n` is 0 or above [`MAX_BLOCKS`]: the study file's parser refuses
/// those first.
pub fn balanced_latin_square(n: usize) -> Vec<Vec<usize>> {
    assert!((1..=MAX_BLOCKS).contains(&n), "a square of {n} blocks");
    // The first row zigzags 0, 1, n-1, 2, n-2, …: consecutive differences
    // are then all distinct mod n (for even n), which is what makes every
    // ordered pair of neighbours appear once once the row is shifted.
    let first: Vec<usize> = (0..n)
        .map(|j| match j {
            0 => 0,
            j if j % 2 == 1 => j.div_ceil(2),
            j => n - j / 2,
        })
        .collect();
    let mut rows: Vec<Vec<usize>> = (0..n).map(|r| first.iter().map(|&c| (c + r) % n).collect()).collect();
    if n % 2 == 1 && n > 1 {
        let mirrored: Vec<Vec<usize>> = rows.iter().map(|row| row.iter().rev().copied().collect()).collect();
        rows.extend(mirrored);
    }
    rows
}
