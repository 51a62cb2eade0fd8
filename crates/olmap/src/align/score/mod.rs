//! The scoring kernels: the grids the searches look scan voxels up in, laid out for their
//! inner loops. [`DenseGrid`] holds a level's free space (one bit per cell of a key box),
//! [`CellGrid`] a level's occupied and free cells for scoring a chunk of translations per
//! pass over the scan, and [`RowGrid`] the same cells as rows for scoring a whole box of
//! translations at once.

pub(super) mod cells;
mod dense;
mod rows;

pub(crate) use self::cells::CellGrid;
pub(crate) use self::dense::DenseGrid;
pub(crate) use self::rows::RowGrid;
