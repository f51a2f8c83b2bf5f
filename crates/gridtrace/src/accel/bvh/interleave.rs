//! Walks of one batch run side by side (`LANES` of them, one step each in turn), a lane
//! refilled with the batch's next item as its walk finishes: the schedule of the ray batches
//! (`walk.rs`), the counting walk (`all_hits.rs`) and the nearest-point searches
//! (`closest.rs`). One walk's step waits on the node it just chose; the others' steps overlap
//! that wait, each prefetching what it visits next.

/// Runs the walks in `lanes` until the batch is done. `next(w, done)` is handed a lane and, if
/// its walk just finished, that walk's item (to take its answer); it starts the batch's next
/// item in the lane and returns its index, or `None` when no item is left. `step(w)` takes one
/// step, true when the walk is finished; `ahead(w)` prefetches for a walk that goes on.
#[inline(always)]
pub(super) fn interleave<W, const N: usize>(
    lanes: &mut [W; N],
    mut next: impl FnMut(&mut W, Option<usize>) -> Option<usize>,
    mut step: impl FnMut(&mut W) -> bool,
    mut ahead: impl FnMut(&W),
) {
    let mut item_of = [None; N];
    let mut active = 0;
    for (w, i) in lanes.iter_mut().zip(&mut item_of) {
        *i = next(w, None);
        active += i.is_some() as usize;
    }
    while active > 0 {
        for (w, i) in lanes.iter_mut().zip(&mut item_of) {
            if i.is_none() {
                continue;
            }
            if step(w) {
                *i = next(w, *i);
                if i.is_none() {
                    active -= 1;
                    continue;
                }
            }
            ahead(w);
        }
    }
}
