//! Trinary (free / occupied / unknown) grids: the cell classes, the thresholds that turn
//! occupancy probabilities into them, and the grid itself. [`super::ros_map`] reads and
//! writes them as ROS map files.

/// The class of a cell in a trinary map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Trinary {
    /// Known to be free.
    Free,
    /// Known to be occupied.
    Occupied,
    /// Not known (never observed, or not certain enough).
    Unknown,
}

impl Trinary {
    /// The pixel ROS `map_saver` writes: 254 free, 0 occupied, 205 unknown.
    pub fn pgm_value(self) -> u8 {
        match self {
            Trinary::Free => 254,
            Trinary::Occupied => 0,
            Trinary::Unknown => 205,
        }
    }
}

/// Probability thresholds of a trinary map (ROS `occupied_thresh` and `free_thresh`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// A cell with a larger probability is occupied (default 0.65).
    pub occupied: f64,
    /// A cell with a smaller probability is free (default 0.196).
    pub free: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            occupied: 0.65,
            free: 0.196,
        }
    }
}

impl Thresholds {
    /// Occupied above `occupied`, free below `free`, unknown otherwise (as `map_server`).
    pub fn classify(&self, p: f64) -> Trinary {
        if p > self.occupied {
            Trinary::Occupied
        } else if p < self.free {
            Trinary::Free
        } else {
            Trinary::Unknown
        }
    }
}

/// A trinary map: what a ROS map PGM + YAML pair holds.
///
/// ```
/// use olmap::grid2d::{read_ros_map, write_ros_map, Thresholds, Trinary, TrinaryGrid};
/// let mut map = TrinaryGrid::unknown(0.05, [-1.0, 2.0, 0.0], 4, 3);
/// map.cells[0] = Trinary::Occupied; // cell (0, 0), the lower-left one
/// map.cells[5] = Trinary::Free; // cell (1, 1)
/// let dir = tempfile::tempdir().unwrap();
/// let yaml = write_ros_map(dir.path().join("map.pgm"), &map).unwrap();
/// assert_eq!(yaml, dir.path().join("map.yaml"));
/// let back = read_ros_map(&yaml).unwrap();
/// assert_eq!(back, map);
/// assert_eq!(back.at_world(-0.99, 2.01), Some(Trinary::Occupied));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct TrinaryGrid {
    /// Metres per cell.
    pub resolution: f64,
    /// World pose `[x, y, yaw]` (metres, radians) of the corner of cell (0, 0).
    pub origin: [f64; 3],
    /// Columns (cells along the map's x).
    pub width: usize,
    /// Rows (cells along the map's y).
    pub height: usize,
    /// The cells row by row, row 0 at the lowest y (`cells[j * width + i]`).
    pub cells: Vec<Trinary>,
    /// The thresholds written to (or read from) the YAML file.
    pub thresholds: Thresholds,
}

impl TrinaryGrid {
    /// A map of unknown cells with the default thresholds.
    pub fn unknown(resolution: f64, origin: [f64; 3], width: usize, height: usize) -> Self {
        TrinaryGrid {
            resolution,
            origin,
            width,
            height,
            cells: vec![Trinary::Unknown; width * height],
            thresholds: Thresholds::default(),
        }
    }

    /// Cell `(i, j)`, `None` outside the map.
    pub fn get(&self, i: usize, j: usize) -> Option<Trinary> {
        (i < self.width && j < self.height).then(|| self.cells[j * self.width + i])
    }

    /// The cell holding the world point `(x, y)` (the origin's yaw is applied), `None`
    /// outside the map.
    pub fn at_world(&self, x: f64, y: f64) -> Option<Trinary> {
        let (s, c) = self.origin[2].sin_cos();
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let u = (c * dx + s * dy) / self.resolution;
        let v = (-s * dx + c * dy) / self.resolution;
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        self.get(u.floor() as usize, v.floor() as usize)
    }

    /// Numbers of free, occupied and unknown cells.
    pub fn counts(&self) -> CellCounts {
        let mut c = CellCounts::default();
        for &t in &self.cells {
            c.add(t);
        }
        c
    }
}

/// Numbers of free, occupied and unknown cells of a grid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CellCounts {
    /// Cells classified free.
    pub free: usize,
    /// Cells classified occupied.
    pub occupied: usize,
    /// Cells neither free nor occupied (never observed, or not certain enough).
    pub unknown: usize,
}

impl CellCounts {
    /// Adds one cell of the given class.
    pub fn add(&mut self, t: Trinary) {
        match t {
            Trinary::Free => self.free += 1,
            Trinary::Occupied => self.occupied += 1,
            Trinary::Unknown => self.unknown += 1,
        }
    }
}
