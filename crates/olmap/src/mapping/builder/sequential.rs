//! The sequential (online) mapper: scans join in the given order, each aligned to the map
//! so far ([`super::MapMode::Sequential`]); and the one step it shares with the incremental
//! mapper ([`try_place`]).

use super::state::State;
use super::{placed_record, Placing};
use crate::error::Result;

/// Places every scan but the frame scan in input order: a trusted registration joins the
/// map, an untrusted one leaves its doubts in `placing`.
pub(super) fn place_in_order(
    state: &mut State<'_>,
    placing: &mut Placing,
    progress: &mut impl FnMut(usize, usize),
) -> Result<()> {
    let (n, first) = (state.scans.len(), state.params.first);
    for s in (0..n).filter(|&s| s != first) {
        try_place(state, placing, s, true)?;
        progress(placing.placed.len(), n);
    }
    Ok(())
}

/// Registers scan `s` against the map as it is ([`State::register`]): a trusted result
/// joins the map (recorded in `placing`, its doubts cleared) and `true` is returned; an
/// untrusted one leaves its doubts in `placing`.
pub(super) fn try_place(
    state: &mut State<'_>,
    placing: &mut Placing,
    s: usize,
    allow_global: bool,
) -> Result<bool> {
    let found = state.register(s, allow_global)?;
    let r = &found.registration;
    if !r.trusted {
        placing.last_doubts[s] = Some(r.doubts.clone());
        return Ok(false);
    }
    state.place(s, r.pose)?;
    let record = placed_record(s, &state.scans[s].name, placing.placed.len(), r, found.via);
    placing.placed.push(record);
    placing.last_doubts[s] = None;
    Ok(true)
}
