//! The sequential (online) mapper: scans join in the given order, each aligned to the map
//! so far ([`super::MapMode::Sequential`]).

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
    let scans = state.scans;
    for s in (0..scans.len()).filter(|&s| s != state.params.first) {
        let found = state.register(s, true)?;
        let r = &found.registration;
        if r.trusted {
            state.place(s, r.pose)?;
            let record = placed_record(s, &scans[s].name, placing.placed.len(), r, found.via);
            placing.placed.push(record);
        } else {
            placing.last_doubts[s] = Some(r.doubts.clone());
        }
        progress(placing.placed.len(), scans.len());
    }
    Ok(())
}
