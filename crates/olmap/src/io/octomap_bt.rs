//! OctoMap binary octree files (`.bt`): a maximum-likelihood occupancy map as a pruned octree.
//!
//! OctoMap (K.M. Wurm, A. Hornung et al., University of Freiburg) stores maps in an octree of
//! fixed depth 16. Its compact `.bt` format keeps only whether each node is free or occupied
//! (`AbstractOccupancyOcTree::writeBinary`); the full-probability `.ot` format is not read
//! here. The layout, as described in the shared data README (§2.4):
//!
//! ```text
//! # Octomap OcTree binary file          first line (only its start is checked)
//! # any comment                         any number of '#' lines
//! id OcTree                             the tree type: only OcTree is accepted
//! size 532566                           number of nodes, root included (0: empty tree)
//! res 0.08                              edge of the finest voxels, metres (> 0)
//! data                                  end of the text header; the binary body follows
//! ```
//!
//! The keyword lines may come in any order; `\r\n` line ends are accepted. The body is the
//! tree in depth-first pre-order, starting at the root, which is always an inner node. An
//! inner node is two bytes holding two bits per child: byte 0 describes children 0-3,
//! byte 1 children 4-7, child `i` in bits `2(i mod 4)` (low) and `2(i mod 4) + 1` (high):
//!
//! | low bit | high bit | child |
//! |---|---|---|
//! | 0 | 0 | unknown (absent) |
//! | 1 | 0 | free leaf |
//! | 0 | 1 | occupied leaf |
//! | 1 | 1 | inner node: its two bytes (and its subtree) follow |
//!
//! The subtrees of the inner children follow the parent's two bytes in child order 0..7.
//! Child index bits: bit 0 = x, bit 1 = y, bit 2 = z (the upper half along that axis).
//! The root is depth 0; a leaf at depth `d` is a cube of `2^(16-d)` voxels per axis, so
//! depth-16 leaves are single voxels of edge `res`. OctoMap's key per axis is
//! `floor(coord / res) + 32768` (an unsigned 16-bit number whose bits, most significant
//! first, pick the child at depths 1..16), so olmap's [`VoxelKey`] is the OctoMap key minus
//! 32768 and a map spans `[-32768 res, 32768 res)` metres per axis.
//!
//! [`read()`] returns the occupied leaves expanded to voxels of the tree resolution (free
//! leaves are only counted), with a caller-given limit on the expanded count;
//! [`read_leaves()`] keeps occupied and free leaves unexpanded, and
//! [`BtLeaves::compare`] compares two trees' classification voxel by voxel. [`write()`]
//! writes a set of occupied voxels as a maximally pruned tree: any node whose eight
//! children are all occupied becomes one occupied leaf, recursively; everything else is
//! unknown. [`write_classified()`] writes free voxels too (a log-odds map's
//! [`crate::occupancy::LogOddsMap::write_bt`]), pruned the same way per state.

use std::io::{BufRead, Write};
use std::path::Path;

use crate::error::{Location, ParseError};
use crate::file::header::{clip, HeaderLines};
use crate::geometry::VoxelKey;

/// The depth of every OctoMap tree: its leaves at this depth are single voxels.
pub const TREE_DEPTH: u32 = 16;

/// The offset between OctoMap's unsigned keys and [`VoxelKey`] indices.
const KEY_OFFSET: i32 = 1 << (TREE_DEPTH - 1);

/// The start of the first line of a `.bt` file.
const MAGIC: &[u8] = b"# Octomap OcTree binary file";

/// The start of the first line of a full-probability `.ot` file.
const OT_MAGIC: &[u8] = b"# Octomap OcTree file";

/// Bytes of memory one expanded voxel takes in a map read by
/// [`crate::occupancy::read_map`] (in its table, with the spare slots; [`read()`]'s sorted
/// list takes twice that while it is built). Used to state what a refused tree would
/// have cost.
pub const BYTES_PER_EXPANDED_VOXEL: u64 = 10;

/// The longest header line accepted (a guard against reading a binary file as one line).
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// What a `.bt` tree holds, counted while reading it (or while writing it, for [`write()`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BtStats {
    /// All nodes of the tree, root, inner nodes and leaves included (the header's `size`).
    pub nodes: u64,
    /// Leaves marked occupied (at any depth).
    pub occupied_leaves: u64,
    /// Leaves marked free (at any depth).
    pub free_leaves: u64,
    /// Occupied leaves per depth (index 16 = single voxels, 15 = 2x2x2 voxels, ...).
    pub occupied_leaves_by_depth: [u64; 17],
}

/// An OctoMap tree read from a `.bt` file: its occupied voxels.
#[derive(Debug, Clone, PartialEq)]
pub struct BtTree {
    /// The edge of the finest voxels (depth-16 leaves), metres.
    pub resolution: f64,
    /// Every occupied voxel at [`BtTree::resolution`] (coarser occupied leaves expanded),
    /// sorted ascending by `(x, y, z)`, without duplicates.
    pub occupied: Vec<VoxelKey>,
    /// What the file's tree holds.
    pub stats: BtStats,
}

/// The keyword lines of the text header.
#[derive(Debug)]
struct Header {
    size: u64,
    resolution: f64,
    /// The byte offset where the body starts.
    data_start: u64,
}

/// A leaf: its depth and its key prefix (the top `depth` bits of the OctoMap key) per axis.
#[derive(Debug, Clone, Copy)]
struct Leaf {
    depth: u32,
    prefix: [u32; 3],
}

impl Leaf {
    /// The OctoMap key of the leaf's lowest corner voxel, per axis, and its edge in voxels.
    fn corner_and_edge(&self) -> ([u32; 3], u32) {
        let shift = TREE_DEPTH - self.depth;
        (self.prefix.map(|p| p << shift), 1 << shift)
    }

    /// The voxels of the tree's resolution the leaf stands for.
    fn volume(&self) -> u64 {
        1u64 << (3 * (TREE_DEPTH - self.depth))
    }

    /// The leaf as a range of Morton codes (see [`morton`]): a leaf's voxels are exactly
    /// the codes from its corner's code on, as many as its volume.
    fn morton_range(&self) -> (u64, u64) {
        let (corner, _) = self.corner_and_edge();
        let start = morton(corner.map(|c| c as u16));
        (start, start + self.volume())
    }
}

// ---------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------

/// Reads a `.bt` OctoMap tree from a stream and expands its occupied leaves to voxels.
///
/// The body must hold exactly the tree: as many nodes as the header's `size`, and no bytes
/// after it. `max_voxels` bounds the number of occupied voxels after expansion (an occupied
/// leaf at depth `d` is `8^(16-d)` voxels); a tree above it is refused with
/// [`ParseError::TooLarge`], which names the expansion and its memory estimate, before
/// anything is expanded.
///
/// Errors: [`ParseError::Empty`] for an empty stream; header problems at their line; body
/// problems at their byte offset (counted from the start of the stream);
/// [`ParseError::Truncated`] when the body ends inside the tree; [`ParseError::Malformed`]
/// for bytes after the tree or a node count that differs from `size`.
///
/// ```
/// use olmap::geometry::VoxelKey;
/// use olmap::io::octomap_bt;
/// let mut file = Vec::new();
/// octomap_bt::write(&mut file, 0.1, &[VoxelKey::new(3, -2, 0)]).unwrap();
/// let tree = octomap_bt::read(&file[..], 1_000_000).unwrap();
/// assert_eq!(tree.resolution, 0.1);
/// assert_eq!(tree.occupied, vec![VoxelKey::new(3, -2, 0)]);
/// ```
pub fn read<R: BufRead>(reader: R, max_voxels: usize) -> Result<BtTree, ParseError> {
    let leaves = read_leaves_keeping(reader, false)?;
    let total = leaves.expanded_voxels_within(max_voxels)?;
    // `total` <= `max_voxels`, so it fits a usize. The voxels are gathered as packed
    // OctoMap keys (x, y, z in 16 bits each, x most significant), whose order as integers
    // is the (x, y, z) order of the voxel keys, and sort faster than the keys themselves.
    let mut packed = Vec::with_capacity(total as usize);
    leaves.for_each_packed(|p| packed.push(p));
    // Leaves are disjoint cubes, so there are no duplicates to remove.
    packed.sort_unstable();
    let occupied = packed.into_iter().map(unpack).collect();
    Ok(BtTree {
        resolution: leaves.resolution,
        occupied,
        stats: leaves.stats,
    })
}

/// The voxel key of a packed OctoMap key (x, y, z in 16 bits each, x most significant).
#[inline]
fn unpack(p: u64) -> VoxelKey {
    let axis = |shift: u32| (p >> shift & 0xFFFF) as i32 - KEY_OFFSET;
    VoxelKey::new(axis(32), axis(16), axis(0))
}

/// A `.bt` tree parsed but not expanded: its resolution, what it holds, and its occupied
/// and free leaves (at any depth). [`BtLeaves::expanded_voxels_within`] says what expanding them
/// would cost before anything is allocated; [`BtLeaves::for_each_voxel`] expands them.
#[derive(Debug, Clone)]
pub struct BtLeaves {
    /// The edge of the finest voxels (depth-16 leaves), metres.
    pub resolution: f64,
    /// What the file's tree holds.
    pub stats: BtStats,
    leaves: Vec<Leaf>,
    free: Vec<Leaf>,
}

impl BtLeaves {
    /// The voxels the occupied leaves expand to (an occupied leaf at depth `d` is
    /// `8^(16-d)` voxels).
    pub fn expanded_voxels(&self) -> u64 {
        self.leaves
            .iter()
            .fold(0u64, |sum, l| sum.saturating_add(l.volume()))
    }

    /// The voxels the free leaves stand for (never expanded).
    pub fn free_voxels(&self) -> u64 {
        self.free
            .iter()
            .fold(0u64, |sum, l| sum.saturating_add(l.volume()))
    }

    /// The free leaves (when kept) as boxes of voxel keys, each its lowest and highest
    /// corner voxel (a leaf at depth `d` is a cube of `2^(16-d)` voxels a side), in the
    /// file's order.
    pub fn free_boxes(&self) -> impl Iterator<Item = (VoxelKey, VoxelKey)> + '_ {
        self.free.iter().map(|leaf| {
            let (corner, edge) = leaf.corner_and_edge();
            let key = |d: u32| {
                let k = corner.map(|c| (c + d) as i32 - KEY_OFFSET);
                VoxelKey::new(k[0], k[1], k[2])
            };
            (key(0), key(edge - 1))
        })
    }

    /// Compares the classification of two trees of one resolution voxel by voxel, without
    /// expanding either (the leaves sorted in Morton order, then swept together). Trees
    /// whose resolutions differ by more than one part in a million (OctoMap writes `res`
    /// with six significant digits) are [`crate::Error::InvalidArgument`].
    ///
    /// ```
    /// use olmap::geometry::VoxelKey;
    /// use olmap::io::octomap_bt;
    /// let (a, b) = (VoxelKey::new(0, 0, 0), VoxelKey::new(1, 0, 0));
    /// let mut one = Vec::new();
    /// octomap_bt::write_classified(&mut one, 0.1, [(a, true), (b, false)]).unwrap();
    /// let mut two = Vec::new();
    /// octomap_bt::write_classified(&mut two, 0.1, [(a, true), (b, true)]).unwrap();
    /// let one = octomap_bt::read_leaves(&one[..]).unwrap();
    /// let two = octomap_bt::read_leaves(&two[..]).unwrap();
    /// let c = one.compare(&two).unwrap();
    /// assert_eq!((c.both_known, c.agree, c.free_here_occupied_there), (2, 1, 1));
    /// assert_eq!(c.agreement(), 0.5);
    /// ```
    pub fn compare(&self, other: &BtLeaves) -> crate::Result<BtComparison> {
        let scale = self.resolution.abs().max(other.resolution.abs());
        if (self.resolution - other.resolution).abs() > 1e-6 * scale {
            return Err(crate::Error::InvalidArgument(format!(
                "trees of different resolutions ({} m and {} m) cannot be compared voxel by voxel",
                self.resolution, other.resolution
            )));
        }
        let a = self.ranges();
        let b = other.ranges();
        let mut c = BtComparison {
            resolution: self.resolution,
            known_here: a.iter().map(|r| r.1 - r.0).sum(),
            known_there: b.iter().map(|r| r.1 - r.0).sum(),
            ..BtComparison::default()
        };
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            let ((sa, ea, oa), (sb, eb, ob)) = (a[i], b[j]);
            let overlap = ea.min(eb).saturating_sub(sa.max(sb));
            if overlap > 0 {
                c.both_known += overlap;
                match (oa, ob) {
                    (true, true) => c.occupied_both += overlap,
                    (false, false) => c.free_both += overlap,
                    (true, false) => c.occupied_here_free_there += overlap,
                    (false, true) => c.free_here_occupied_there += overlap,
                }
            }
            if ea <= eb {
                i += 1;
            } else {
                j += 1;
            }
        }
        c.agree = c.occupied_both + c.free_both;
        Ok(c)
    }

    /// A lookup of the state of any voxel, without expanding the tree (24 bytes per leaf,
    /// a binary search per lookup).
    ///
    /// ```
    /// use olmap::geometry::VoxelKey;
    /// use olmap::io::octomap_bt;
    /// let mut file = Vec::new();
    /// octomap_bt::write_classified(&mut file, 0.1, [(VoxelKey::new(0, 0, 0), true), (VoxelKey::new(1, 0, 0), false)]).unwrap();
    /// let index = octomap_bt::read_leaves(&file[..]).unwrap().index();
    /// assert_eq!(index.state(&VoxelKey::new(0, 0, 0)), Some(true));
    /// assert_eq!(index.state(&VoxelKey::new(1, 0, 0)), Some(false));
    /// assert_eq!(index.state(&VoxelKey::new(2, 0, 0)), None);
    /// ```
    pub fn index(&self) -> BtIndex {
        BtIndex {
            ranges: self.ranges(),
        }
    }

    /// Every leaf as a Morton range with its state (occupied = true), sorted.
    fn ranges(&self) -> Vec<(u64, u64, bool)> {
        let mut r: Vec<(u64, u64, bool)> = self
            .leaves
            .iter()
            .map(|l| (l, true))
            .chain(self.free.iter().map(|l| (l, false)))
            .map(|(l, occ)| {
                let (s, e) = l.morton_range();
                (s, e, occ)
            })
            .collect();
        r.sort_unstable();
        r
    }

    /// [`BtLeaves::expanded_voxels`], or [`ParseError::TooLarge`] naming the expansion
    /// and its memory estimate when it is above `max_voxels`.
    pub fn expanded_voxels_within(&self, max_voxels: usize) -> Result<u64, ParseError> {
        let total = self.expanded_voxels();
        if total <= max_voxels as u64 {
            return Ok(total);
        }
        let coarse: u64 = self.stats.occupied_leaves_by_depth[..TREE_DEPTH as usize]
            .iter()
            .sum();
        Err(ParseError::TooLarge {
            what: format!(
                "the {} occupied leaves ({coarse} of them coarser than one voxel) expand to \
                 {total} voxels of {} m, about {} MiB as a map",
                self.stats.occupied_leaves,
                self.resolution,
                total.saturating_mul(BYTES_PER_EXPANDED_VOXEL) >> 20
            ),
            limit: format!("{max_voxels} voxels"),
        })
    }

    /// Calls `f` with every occupied voxel, leaf by leaf in the file's order (each leaf's
    /// voxels in (x, y, z) order). Check the cost first
    /// ([`BtLeaves::expanded_voxels_within`]).
    pub fn for_each_voxel(&self, mut f: impl FnMut(VoxelKey)) {
        self.for_each_packed(|p| f(unpack(p)));
    }

    fn for_each_packed(&self, mut f: impl FnMut(u64)) {
        for leaf in &self.leaves {
            let (corner, edge) = leaf.corner_and_edge();
            for x in corner[0]..corner[0] + edge {
                for y in corner[1]..corner[1] + edge {
                    let xy = u64::from(x) << 32 | u64::from(y) << 16;
                    for z in corner[2]..corner[2] + edge {
                        f(xy | u64::from(z));
                    }
                }
            }
        }
    }
}

/// Reads a `.bt` OctoMap tree from a stream without expanding it: memory in proportion to
/// the file (16 bytes per occupied or free leaf), whatever its leaves stand for. Errors as
/// for [`read()`], but for the limit.
pub fn read_leaves<R: BufRead>(reader: R) -> Result<BtLeaves, ParseError> {
    read_leaves_keeping(reader, true)
}

/// [`read_leaves()`], keeping the free leaves or only counting them (what reading a map
/// of occupied voxels needs: OctoMap maps are mostly free leaves).
pub(crate) fn read_leaves_keeping<R: BufRead>(
    reader: R,
    keep_free: bool,
) -> Result<BtLeaves, ParseError> {
    let (header, stats, leaves, free) = parse(reader, keep_free)?;
    Ok(BtLeaves {
        resolution: header.resolution,
        stats,
        leaves,
        free,
    })
}

/// The leaves of a `.bt` tree as sorted Morton ranges: the state of any voxel by binary
/// search ([`BtLeaves::index`]).
#[derive(Debug, Clone)]
pub struct BtIndex {
    ranges: Vec<(u64, u64, bool)>,
}

impl BtIndex {
    /// `Some(true)` for an occupied voxel, `Some(false)` for a free one, `None` when the
    /// tree does not know it (or it is outside OctoMap's key range).
    pub fn state(&self, key: &VoxelKey) -> Option<bool> {
        let code = morton(octomap_key(key)?);
        let i = self.ranges.partition_point(|r| r.0 <= code);
        let (_, end, occupied) = *self.ranges.get(i.checked_sub(1)?)?;
        (code < end).then_some(occupied)
    }

    /// Whether the tree has free leaves (a tree written with free space).
    pub fn has_free(&self) -> bool {
        self.ranges.iter().any(|r| !r.2)
    }
}

/// How two trees classify the voxels of one resolution ([`BtLeaves::compare`]); counts are
/// voxels of that resolution ("here" is the tree `compare` was called on).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BtComparison {
    /// The trees' voxel edge, metres.
    pub resolution: f64,
    /// Voxels known (free or occupied) in this tree.
    pub known_here: u64,
    /// Voxels known in the other tree.
    pub known_there: u64,
    /// Voxels known in both.
    pub both_known: u64,
    /// Voxels known in both with the same state.
    pub agree: u64,
    /// Occupied in both.
    pub occupied_both: u64,
    /// Free in both.
    pub free_both: u64,
    /// Occupied here, free there.
    pub occupied_here_free_there: u64,
    /// Free here, occupied there.
    pub free_here_occupied_there: u64,
}

impl BtComparison {
    /// The fraction of the voxels known to both trees that they classify alike (1 when
    /// none is known to both).
    pub fn agreement(&self) -> f64 {
        if self.both_known == 0 {
            1.0
        } else {
            self.agree as f64 / self.both_known as f64
        }
    }
}

/// Reads a `.bt` OctoMap tree from a file without expanding it; see [`read_leaves()`].
pub fn read_leaves_path(path: &Path) -> crate::Result<BtLeaves> {
    crate::file::parse_file(path, "OctoMap .bt", read_leaves)
}

/// Reads a `.bt` OctoMap tree from a file; see [`read()`].
pub fn read_path(path: &Path, max_voxels: usize) -> crate::Result<BtTree> {
    crate::file::parse_file(path, "OctoMap .bt", |r| read(r, max_voxels))
}

/// The occupied and the free leaves of a tree, unexpanded.
type Parsed = (Header, BtStats, Vec<Leaf>, Vec<Leaf>);

/// Parses header and body, returning the occupied and the free leaves unexpanded.
fn parse<R: BufRead>(mut reader: R, keep_free: bool) -> Result<Parsed, ParseError> {
    let header = parse_header(&mut reader)?;
    let mut body = Body {
        r: reader,
        offset: header.data_start,
    };
    let mut stats = BtStats::default();
    let mut leaves = Vec::new();
    let mut free = Vec::new();
    if header.size > 0 {
        let free = keep_free.then_some(&mut free);
        parse_tree(&mut body, header.size, &mut stats, &mut leaves, free)?;
    }
    let end = body.offset;
    let rest = body.count_rest()?;
    if rest > 0 {
        return Err(ParseError::Malformed(if header.size == 0 {
            format!(
                "{rest} bytes follow the 'data' line (byte {end}) but 'size 0' announces an \
                 empty tree with no body"
            )
        } else {
            format!(
                "{rest} bytes remain after the end of the tree at byte {end} (the tree has {} \
                 nodes, the header's size is {})",
                stats.nodes, header.size
            )
        }));
    }
    if stats.nodes != header.size {
        return Err(ParseError::Malformed(format!(
            "the header's 'size {}' does not match the tree, which has {} nodes",
            header.size, stats.nodes
        )));
    }
    Ok((header, stats, leaves, free))
}

/// The single value of a keyword line, or an error naming the keyword and what it expects.
fn single_value<'a>(
    keyword: &str,
    args: &[&'a [u8]],
    line_no: usize,
    expected: &str,
) -> Result<&'a [u8], ParseError> {
    match args {
        [v] => Ok(v),
        [] => Err(ParseError::line(
            line_no,
            format!("'{keyword}' without a value: expected {expected}"),
        )),
        _ => Err(ParseError::line(
            line_no,
            format!(
                "'{keyword}' with {} values: expected one, {expected}",
                args.len()
            ),
        )),
    }
}

/// Parses the text header up to and including the `data` line.
fn parse_header<R: BufRead>(r: &mut R) -> Result<Header, ParseError> {
    let mut lines = HeaderLines::new(
        r,
        MAX_HEADER_LINE,
        "expected a '#' comment or one of the keywords id, size, res, data",
    );
    let Some(first) = lines.next_line()? else {
        return Err(ParseError::Empty);
    };
    check_first_line(first.bytes)?;
    let mut keywords = Keywords::default();
    loop {
        let Some(line) = lines.next_line()? else {
            return Err(ParseError::Truncated(format!(
                "the header ends after line {} without a 'data' line",
                lines.lines()
            )));
        };
        let line_no = line.number;
        if line.is_comment() {
            continue;
        }
        let words: Vec<&[u8]> = line.words().collect();
        let Some((&keyword, args)) = words.split_first() else {
            continue; // blank line
        };
        if keyword == b"data" {
            return keywords.finish(args, line_no, line.end);
        }
        keywords.take(keyword, args, line_no)?;
    }
}

/// Checks the first line of the header: the `.bt` magic (a `.ot` file gets its own error).
fn check_first_line(first: &[u8]) -> Result<(), ParseError> {
    if !first.starts_with(MAGIC) {
        if first.starts_with(OT_MAGIC) {
            return Err(ParseError::Unsupported(
                "this is a full-probability OctoMap tree (.ot, '# Octomap OcTree file'); only \
                 binary .bt trees are read"
                    .into(),
            ));
        }
        return Err(ParseError::line(
            1,
            format!(
                "expected '{}' as the first line, found '{}'",
                String::from_utf8_lossy(MAGIC),
                clip(first)
            ),
        ));
    }
    Ok(())
}

/// The keyword lines of the header seen so far.
#[derive(Debug, Default)]
struct Keywords {
    id_seen: bool,
    size: Option<u64>,
    resolution: Option<f64>,
}

impl Keywords {
    /// Takes an `id`, `size` or `res` line (`keyword` and the words after it); any other
    /// keyword is an error (the caller handles `data`).
    fn take(&mut self, keyword: &[u8], args: &[&[u8]], line_no: usize) -> Result<(), ParseError> {
        let repeated = |name: &str| {
            ParseError::line(
                line_no,
                format!("a second '{name}' line: each keyword may appear once"),
            )
        };
        match keyword {
            b"id" => {
                if self.id_seen {
                    return Err(repeated("id"));
                }
                let v = single_value("id", args, line_no, "the tree type 'OcTree'")?;
                if v != b"OcTree" {
                    return Err(ParseError::line(
                        line_no,
                        format!(
                            "'id {}': only plain occupancy trees ('id OcTree') are supported",
                            clip(v)
                        ),
                    ));
                }
                self.id_seen = true;
            }
            b"size" => {
                if self.size.is_some() {
                    return Err(repeated("size"));
                }
                let expected = "the node count (a non-negative integer)";
                let v = single_value("size", args, line_no, expected)?;
                let parsed = std::str::from_utf8(v)
                    .ok()
                    .and_then(|s| s.parse::<u64>().ok());
                self.size = Some(parsed.ok_or_else(|| {
                    ParseError::line(line_no, format!("'size {}': expected {expected}", clip(v)))
                })?);
            }
            b"res" => {
                if self.resolution.is_some() {
                    return Err(repeated("res"));
                }
                let expected = "the resolution in metres (a positive finite number)";
                let v = single_value("res", args, line_no, expected)?;
                let parsed = std::str::from_utf8(v)
                    .ok()
                    .and_then(|s| s.parse::<f64>().ok())
                    .filter(|r| r.is_finite() && *r > 0.0);
                self.resolution = Some(parsed.ok_or_else(|| {
                    ParseError::line(line_no, format!("'res {}': expected {expected}", clip(v)))
                })?);
            }
            other => {
                return Err(ParseError::line(
                    line_no,
                    format!(
                        "unknown header keyword '{}': expected a '#' comment or one of id, size, \
                         res, data",
                        clip(other)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The header at the `data` line (`args`: the words after `data`, at `line_no`), the
    /// body starting at byte `data_start`.
    fn finish(self, args: &[&[u8]], line_no: usize, data_start: u64) -> Result<Header, ParseError> {
        if !args.is_empty() {
            return Err(ParseError::line(
                line_no,
                "'data' followed by more text: expected 'data' alone on its line",
            ));
        }
        let missing: Vec<&str> = [
            (!self.id_seen).then_some("id"),
            self.size.is_none().then_some("size"),
            self.resolution.is_none().then_some("res"),
        ]
        .into_iter()
        .flatten()
        .collect();
        match (self.size, self.resolution) {
            (Some(size), Some(resolution)) if self.id_seen => Ok(Header {
                size,
                resolution,
                data_start,
            }),
            _ => Err(ParseError::line(
                line_no,
                format!(
                    "'data' before the {} line(s): expected id, size and res before data",
                    missing.join(", ")
                ),
            )),
        }
    }
}

/// The binary body, read two bytes at a time, with the offset in the whole stream.
struct Body<R> {
    r: R,
    offset: u64,
}

impl<R: BufRead> Body<R> {
    /// Reads the two child-bit bytes of an inner node (`what` names it for errors).
    fn inner_node(&mut self, what: impl FnOnce() -> String) -> Result<u16, ParseError> {
        let start = self.offset;
        let mut out = [0u8; 2];
        let mut got = 0;
        while got < 2 {
            let buf = match self.r.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            };
            if buf.is_empty() {
                return Err(ParseError::Truncated(format!(
                    "{} at byte {start} needs 2 bytes, {got} left",
                    what()
                )));
            }
            let n = (2 - got).min(buf.len());
            out[got..got + n].copy_from_slice(&buf[..n]);
            self.r.consume(n);
            got += n;
        }
        self.offset += 2;
        Ok(u16::from_le_bytes(out))
    }

    /// Reads the rest of the stream, returning how many bytes it held.
    fn count_rest(&mut self) -> Result<u64, ParseError> {
        let mut total = 0u64;
        loop {
            let n = match self.r.fill_buf() {
                Ok(b) => b.len(),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            };
            if n == 0 {
                return Ok(total);
            }
            self.r.consume(n);
            total += n as u64;
        }
    }
}

/// An inner node being visited: its depth, key prefix, child bits, where its two bytes are,
/// and the next child to look at.
struct Frame {
    depth: u32,
    prefix: [u32; 3],
    bits: u16,
    at: u64,
    next: u32,
}

/// Parses the tree in pre-order with an explicit stack (at most 16 frames deep), counting
/// nodes against the header's `size` as it goes.
fn parse_tree<R: BufRead>(
    body: &mut Body<R>,
    size: u64,
    stats: &mut BtStats,
    leaves: &mut Vec<Leaf>,
    mut free: Option<&mut Vec<Leaf>>,
) -> Result<(), ParseError> {
    let at = body.offset;
    let bits = body.inner_node(|| "the root node".to_string())?;
    stats.nodes = 1;
    let mut stack = Vec::with_capacity(TREE_DEPTH as usize + 1);
    stack.push(Frame {
        depth: 0,
        prefix: [0; 3],
        bits,
        at,
        next: 0,
    });
    while let Some(top) = stack.last_mut() {
        // Skip the unknown children (bits 00) at once.
        let remaining = top.bits.checked_shr(2 * top.next).unwrap_or(0);
        if remaining == 0 {
            stack.pop();
            continue;
        }
        let i = top.next + remaining.trailing_zeros() / 2;
        top.next = i + 1;
        let code = (top.bits >> (2 * i)) & 0b11;
        let depth = top.depth + 1;
        let prefix = [
            top.prefix[0] << 1 | (i & 1),
            top.prefix[1] << 1 | (i >> 1 & 1),
            top.prefix[2] << 1 | (i >> 2 & 1),
        ];
        let parent_byte = top.at + u64::from(i / 4);
        if stats.nodes >= size {
            return Err(ParseError::at(
                Location::Byte(parent_byte),
                format!("the tree has more nodes than the header's 'size {size}'"),
            ));
        }
        stats.nodes += 1;
        match code {
            0b01 => {
                stats.free_leaves += 1;
                if let Some(free) = free.as_mut() {
                    free.push(Leaf { depth, prefix });
                }
            }
            0b10 => {
                stats.occupied_leaves += 1;
                stats.occupied_leaves_by_depth[depth as usize] += 1;
                leaves.push(Leaf { depth, prefix });
            }
            _ => {
                // 0b11, an inner node (0b00 children were skipped above).
                if depth >= TREE_DEPTH {
                    return Err(ParseError::at(
                        Location::Byte(parent_byte),
                        format!(
                            "child {i} of a depth-{} node is marked as an inner node (bits 11), \
                             but nodes at depth {TREE_DEPTH} must be leaves",
                            depth - 1
                        ),
                    ));
                }
                let at = body.offset;
                let bits = body.inner_node(|| {
                    format!(
                        "the inner node at depth {depth} (node {} in pre-order)",
                        stats.nodes - 1
                    )
                })?;
                stack.push(Frame {
                    depth,
                    prefix,
                    bits,
                    at,
                    next: 0,
                });
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------

/// Writes a set of occupied voxels as a `.bt` OctoMap tree and returns what the tree holds.
///
/// The tree is maximally pruned: a node whose eight children are all occupied is written as
/// one occupied leaf, recursively (but the root is always an inner node, as the format
/// needs). No free leaves are written: everything else is unknown. `occupied` may be in any
/// order and hold duplicates. Every index must lie in `-32768..=32767` (OctoMap's 16-bit
/// keys), and `resolution` must be positive and finite; otherwise the error is of kind
/// [`std::io::ErrorKind::InvalidInput`] and nothing is written.
///
/// The header is `# Octomap OcTree binary file`, `# (written by olmap)`, `id OcTree`,
/// `size <nodes>`, `res <resolution>` (shortest exact decimal), `data`.
pub fn write<W: Write>(w: W, resolution: f64, occupied: &[VoxelKey]) -> std::io::Result<BtStats> {
    write_classified(w, resolution, occupied.iter().map(|k| (*k, true)))
}

/// Writes voxels that are occupied (`true`) or free (`false`) as a `.bt` OctoMap tree and
/// returns what the tree holds: the maximum-likelihood tree OctoMap writes, maximally
/// pruned (a node whose eight children are leaves of one state is written as one leaf of
/// that state, recursively; the root is always an inner node). Voxels not given are
/// unknown. A voxel given twice is occupied if either says so. Key range, resolution and
/// errors as for [`write()`]. Memory: 8 bytes per voxel.
pub fn write_classified<W: Write>(
    mut w: W,
    resolution: f64,
    voxels: impl IntoIterator<Item = (VoxelKey, bool)>,
) -> std::io::Result<BtStats> {
    if !(resolution.is_finite() && resolution > 0.0) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("OctoMap resolution {resolution}: expected a positive finite number of metres"),
        ));
    }
    let voxels = voxels.into_iter();
    let mut codes = Vec::with_capacity(voxels.size_hint().0);
    for (k, occupied) in voxels {
        let key = octomap_key(&k).ok_or_else(|| {
            let lo = -f64::from(KEY_OFFSET) * resolution;
            let hi = f64::from(KEY_OFFSET) * resolution;
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "voxel key ({}, {}, {}) is outside OctoMap's key range: each index must be \
                     in -32768..=32767, i.e. coordinates in [{lo}, {hi}) m at {resolution} m",
                    k.x, k.y, k.z
                ),
            )
        })?;
        // The state in the lowest bit: sorted codes stay in Morton order.
        codes.push(morton(key) << 1 | u64::from(occupied));
    }
    codes.sort_unstable();
    // `a` is dropped when it has `b`'s key; `b` keeps "occupied" if either had it.
    codes.dedup_by(|a, b| {
        let same = *a >> 1 == *b >> 1;
        if same {
            *b |= *a & 1;
        }
        same
    });
    let mut stats = BtStats::default();
    // Worst case 2 bytes per inner node; a few inner nodes per voxel at most near the root,
    // usually far fewer.
    let mut body = Vec::with_capacity(codes.len().saturating_mul(2).min(1 << 26));
    if !codes.is_empty() {
        stats.nodes = 1;
        write_inner(&codes, 0, &mut body, &mut stats);
    }
    let header = format!(
        "# Octomap OcTree binary file\n# (written by olmap)\nid OcTree\nsize {}\nres {}\ndata\n",
        stats.nodes, resolution
    );
    w.write_all(header.as_bytes())?;
    w.write_all(&body)?;
    Ok(stats)
}

/// Writes classified voxels as a `.bt` OctoMap tree file; see [`write_classified()`]. The
/// file appears complete or not at all.
pub fn write_classified_path(
    path: &Path,
    resolution: f64,
    voxels: impl IntoIterator<Item = (VoxelKey, bool)>,
) -> crate::Result<BtStats> {
    let mut stats = None;
    crate::file::write_atomic(path, "OctoMap .bt", |w| {
        stats = Some(write_classified(w, resolution, voxels)?);
        Ok(())
    })?;
    Ok(stats.unwrap_or_default())
}

/// Writes a set of occupied voxels as a `.bt` OctoMap tree file; see [`write()`]. The file
/// appears complete or not at all.
pub fn write_path(path: &Path, resolution: f64, occupied: &[VoxelKey]) -> crate::Result<BtStats> {
    let mut stats = None;
    crate::file::write_atomic(path, "OctoMap .bt", |w| {
        stats = Some(write(w, resolution, occupied)?);
        Ok(())
    })?;
    Ok(stats.unwrap_or_default())
}

/// The OctoMap key of a voxel, or `None` outside the 16-bit range.
fn octomap_key(k: &VoxelKey) -> Option<[u16; 3]> {
    let f = |v: i32| u16::try_from(i64::from(v) + i64::from(KEY_OFFSET)).ok();
    Some([f(k.x)?, f(k.y)?, f(k.z)?])
}

/// Interleaves the bits of an OctoMap key into a 48-bit Morton code whose 3-bit groups,
/// from the most significant, are the child indices at depths 1..16 (z, y, x; x lowest).
/// Sorted codes are in the tree's depth-first child order.
fn morton(key: [u16; 3]) -> u64 {
    let mut m = 0u64;
    for bit in 0..TREE_DEPTH {
        for (axis, &k) in key.iter().enumerate() {
            m |= u64::from(k >> bit & 1) << (3 * bit + axis as u32);
        }
    }
    m
}

/// Writes the inner node at `depth` covering the sorted `codes` (Morton code shifted left
/// by one, the lowest bit set for occupied; distinct Morton codes; all sharing the node's
/// prefix), then the subtrees of its inner children. Recursion is at most 16 deep.
fn write_inner(codes: &[u64], depth: u32, out: &mut Vec<u8>, stats: &mut BtStats) {
    let child_depth = depth + 1;
    let shift = 3 * (TREE_DEPTH - child_depth) + 1;
    // A child cube holds 8^(16 - child_depth) voxels; all present and of one state make
    // a leaf of that state.
    let full = 1u64 << (shift - 1);
    let mut groups: [&[u64]; 8] = [&[]; 8];
    let mut rest = codes;
    for (i, group) in groups.iter_mut().enumerate() {
        let n = rest.partition_point(|&m| (m >> shift & 7) as usize <= i);
        (*group, rest) = rest.split_at(n);
    }
    let mut bits = 0u16;
    let mut inner = [false; 8];
    for (i, group) in groups.iter().enumerate() {
        if group.is_empty() {
            continue;
        }
        stats.nodes += 1;
        let occupied = group.iter().filter(|&&c| c & 1 == 1).count();
        let code = if group.len() as u64 == full && occupied == group.len() {
            stats.occupied_leaves += 1;
            stats.occupied_leaves_by_depth[child_depth as usize] += 1;
            0b10
        } else if group.len() as u64 == full && occupied == 0 {
            stats.free_leaves += 1;
            0b01
        } else {
            inner[i] = true;
            0b11
        };
        bits |= code << (2 * i);
    }
    out.extend_from_slice(&bits.to_le_bytes());
    for (group, _) in groups.iter().zip(inner).filter(|(_, is_inner)| *is_inner) {
        write_inner(group, child_depth, out, stats);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const LIMIT: usize = 1 << 20;

    fn written(res: f64, keys: &[VoxelKey]) -> (Vec<u8>, BtStats) {
        let mut buf = Vec::new();
        let stats = write(&mut buf, res, keys).unwrap();
        (buf, stats)
    }

    /// Splits a written file into header and body.
    fn body_of(file: &[u8]) -> &[u8] {
        let pos = file
            .windows(6)
            .position(|w| w == b"\ndata\n")
            .expect("a data line");
        &file[pos + 6..]
    }

    fn file(header: &str, body: &[u8]) -> Vec<u8> {
        let mut v = header.as_bytes().to_vec();
        v.extend_from_slice(body);
        v
    }

    fn header(size: u64) -> String {
        format!("# Octomap OcTree binary file\nid OcTree\nsize {size}\nres 0.1\ndata\n")
    }

    fn sorted_set(keys: &[VoxelKey]) -> Vec<VoxelKey> {
        let mut v = keys.to_vec();
        v.sort_unstable();
        v.dedup();
        v
    }

    fn block(origin: VoxelKey, edge: i32) -> Vec<VoxelKey> {
        let mut v = Vec::new();
        for x in 0..edge {
            for y in 0..edge {
                for z in 0..edge {
                    v.push(VoxelKey::new(origin.x + x, origin.y + y, origin.z + z));
                }
            }
        }
        v
    }

    #[test]
    fn geb079_real_map() {
        let Some(dir) = crate::test_data::dir() else {
            return;
        };
        let path = dir.join("octomap_share_data/geb079.bt");
        let tree = read_path(&path, 10_000_000).unwrap();
        assert_eq!(tree.resolution, 0.08);
        let s = &tree.stats;
        assert_eq!(s.nodes, 532_566);
        assert_eq!(s.occupied_leaves, 143_729);
        assert_eq!(s.free_leaves, 284_415);
        let mut by_depth = [0u64; 17];
        by_depth[16] = 137_745;
        by_depth[15] = 5_983;
        by_depth[14] = 1;
        assert_eq!(s.occupied_leaves_by_depth, by_depth);
        assert_eq!(tree.occupied.len(), 137_745 + 5_983 * 8 + 64);
        assert_eq!(tree.occupied.len(), 185_673);
        assert!(tree.occupied.windows(2).all(|w| w[0] < w[1]));

        // Occupied-leaf centres (README §2.4): x -7.96..30.92, y -7.48..7.40, z -0.28..2.76.
        let expected = [[-7.96, 30.92], [-7.48, 7.40], [-0.28, 2.76]];
        let (_, _, leaves, _) = parse(&std::fs::read(&path).unwrap()[..], false).unwrap();
        let bounds = |centres: &mut dyn Iterator<Item = [f64; 3]>| {
            let mut b = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
            for c in centres {
                for a in 0..3 {
                    b[a][0] = b[a][0].min(c[a]);
                    b[a][1] = b[a][1].max(c[a]);
                }
            }
            b
        };
        let leaf_centre = |l: &Leaf| {
            let (corner, edge) = l.corner_and_edge();
            corner.map(|c| (c as f64 - KEY_OFFSET as f64 + edge as f64 / 2.0) * 0.08)
        };
        let fine = bounds(&mut leaves.iter().filter(|l| l.depth == 16).map(leaf_centre));
        let all = bounds(&mut leaves.iter().map(leaf_centre));
        for a in 0..3 {
            for e in 0..2 {
                assert!((fine[a][e] - expected[a][e]).abs() < 1e-2, "{fine:?}");
                assert!((all[a][e] - expected[a][e]).abs() < 1e-2, "{all:?}");
            }
        }
        let voxels = bounds(&mut tree.occupied.iter().map(|k| {
            let c = k.center(0.08);
            [c.x, c.y, c.z]
        }));
        for a in 0..3 {
            assert!(voxels[a][0] <= expected[a][0] + 1e-2, "{voxels:?}");
            assert!(voxels[a][1] >= expected[a][1] - 1e-2, "{voxels:?}");
        }

        // Write the occupied set, read it back, write it again.
        let (bytes, ws) = written(0.08, &tree.occupied);
        let back = read(&bytes[..], 10_000_000).unwrap();
        assert_eq!(back.resolution, 0.08);
        assert_eq!(back.occupied, tree.occupied);
        assert_eq!(back.stats, ws);
        assert_eq!(ws.free_leaves, 0);
        assert!(ws.occupied_leaves <= tree.occupied.len() as u64);
        // Maximal pruning never needs more occupied leaves than OctoMap's own tree.
        assert!(ws.occupied_leaves <= s.occupied_leaves, "{ws:?}");
        let (again, _) = written(0.08, &back.occupied);
        assert_eq!(again, bytes);
    }

    #[test]
    fn single_voxel_at_origin() {
        let (bytes, stats) = written(0.1, &[VoxelKey::new(0, 0, 0)]);
        // OctoMap key 32768 = 1000..0: child 7 at depth 1, then child 0 down to the leaf.
        let mut expected = vec![0x00, 0xC0];
        for _ in 1..15 {
            expected.extend_from_slice(&[0x03, 0x00]);
        }
        expected.extend_from_slice(&[0x02, 0x00]);
        assert_eq!(body_of(&bytes), &expected[..]);
        assert_eq!(stats.nodes, 17);
        assert_eq!(stats.occupied_leaves, 1);
        assert_eq!(stats.occupied_leaves_by_depth[16], 1);
        assert!(bytes.starts_with(
            b"# Octomap OcTree binary file\n# (written by olmap)\nid OcTree\nsize 17\nres 0.1\ndata\n"
        ));
        let back = read(&bytes[..], LIMIT).unwrap();
        assert_eq!(back.occupied, vec![VoxelKey::new(0, 0, 0)]);
        assert_eq!(back.stats, stats);
    }

    #[test]
    fn single_voxel_at_minus_one() {
        let (bytes, stats) = written(0.25, &[VoxelKey::new(-1, -1, -1)]);
        // OctoMap key 32767 = 0111..1: child 0 at depth 1, then child 7 down to the leaf.
        let mut expected = vec![0x03, 0x00];
        for _ in 1..15 {
            expected.extend_from_slice(&[0x00, 0xC0]);
        }
        expected.extend_from_slice(&[0x00, 0x80]);
        assert_eq!(body_of(&bytes), &expected[..]);
        assert_eq!(stats.nodes, 17);
        let back = read(&bytes[..], LIMIT).unwrap();
        assert_eq!(back.resolution, 0.25);
        assert_eq!(back.occupied, vec![VoxelKey::new(-1, -1, -1)]);
    }

    #[test]
    fn aligned_blocks_prune_and_unaligned_do_not() {
        let cube = block(VoxelKey::new(0, 0, 0), 2);
        let (bytes, stats) = written(0.1, &cube);
        assert_eq!(stats.occupied_leaves, 1);
        assert_eq!(stats.occupied_leaves_by_depth[15], 1);
        assert_eq!(stats.nodes, 16);
        assert_eq!(read(&bytes[..], LIMIT).unwrap().occupied, sorted_set(&cube));

        let cube = block(VoxelKey::new(-4, 8, -12), 4);
        let (bytes, stats) = written(0.1, &cube);
        assert_eq!(stats.occupied_leaves, 1);
        assert_eq!(stats.occupied_leaves_by_depth[14], 1);
        assert_eq!(read(&bytes[..], LIMIT).unwrap().occupied, sorted_set(&cube));

        let cube = block(VoxelKey::new(1, 0, 0), 2);
        let (bytes, stats) = written(0.1, &cube);
        assert_eq!(stats.occupied_leaves, 8);
        assert_eq!(stats.occupied_leaves_by_depth[16], 8);
        assert_eq!(read(&bytes[..], LIMIT).unwrap().occupied, sorted_set(&cube));

        // Duplicates and order do not matter.
        let mut shuffled = cube.clone();
        shuffled.reverse();
        shuffled.extend_from_slice(&cube);
        assert_eq!(written(0.1, &shuffled).0, bytes);
    }

    #[test]
    fn empty_tree_round_trips() {
        let (bytes, stats) = written(0.05, &[]);
        assert_eq!(
            bytes,
            b"# Octomap OcTree binary file\n# (written by olmap)\nid OcTree\nsize 0\nres 0.05\ndata\n"
        );
        assert_eq!(stats, BtStats::default());
        let back = read(&bytes[..], LIMIT).unwrap();
        assert!(back.occupied.is_empty());
        assert_eq!(back.stats, stats);
        assert_eq!(back.resolution, 0.05);
    }

    #[test]
    fn key_range_limits() {
        let edge = [
            VoxelKey::new(-32768, 32767, 0),
            VoxelKey::new(32767, -32768, -32768),
        ];
        let (bytes, _) = written(1.0, &edge);
        assert_eq!(read(&bytes[..], LIMIT).unwrap().occupied, sorted_set(&edge));
        for bad in [
            VoxelKey::new(32768, 0, 0),
            VoxelKey::new(0, -32769, 0),
            VoxelKey::new(0, 0, i32::MIN),
        ] {
            let mut buf = Vec::new();
            let e = write(&mut buf, 0.1, &[VoxelKey::new(0, 0, 0), bad]).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
            let msg = e.to_string();
            assert!(
                msg.contains("-32768..=32767") && msg.contains("3276.8"),
                "{msg}"
            );
            assert!(buf.is_empty());
        }
        for res in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = write(Vec::new(), res, &[]).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        }
    }

    #[test]
    fn write_path_and_read_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.bt");
        let keys = block(VoxelKey::new(2, 2, 2), 2);
        let stats = write_path(&path, 0.2, &keys).unwrap();
        assert_eq!(stats.occupied_leaves, 1);
        let tree = read_path(&path, LIMIT).unwrap();
        assert_eq!(tree.occupied, sorted_set(&keys));
        assert_eq!(tree.stats, stats);
        let e = read_path(&dir.path().join("missing.bt"), LIMIT).unwrap_err();
        assert!(matches!(e, crate::Error::Io { .. }), "{e}");
    }

    #[test]
    fn coarse_leaves_expand_within_the_limit() {
        // One occupied depth-14 leaf (child 0 down from the root): 64 voxels.
        let mut body = Vec::new();
        for _ in 0..13 {
            body.extend_from_slice(&[0x03, 0x00]);
        }
        body.extend_from_slice(&[0x02, 0x00]);
        let bytes = file(&header(15), &body);
        let tree = read(&bytes[..], 64).unwrap();
        assert_eq!(tree.occupied.len(), 64);
        assert_eq!(tree.occupied[0], VoxelKey::new(-32768, -32768, -32768));
        assert_eq!(tree.occupied[63], VoxelKey::new(-32765, -32765, -32765));
        assert_eq!(tree.stats.occupied_leaves_by_depth[14], 1);
        assert!(matches!(
            read(&bytes[..], 63),
            Err(ParseError::TooLarge { what, .. }) if what.contains("64 voxels")
        ));
        // An occupied depth-1 leaf would be 8^15 voxels: refused, nothing allocated.
        let huge = file(&header(2), &[0x02, 0x00]);
        assert!(matches!(
            read(&huge[..], LIMIT),
            Err(ParseError::TooLarge { what, .. }) if what.contains("35184372088832 voxels")
        ));
    }

    #[test]
    fn free_leaves_are_counted_not_returned() {
        // Root: child 0 free, child 3 inner; then child 0 inner down to depth 15, whose
        // child 0 is free and child 4 occupied.
        let mut body = vec![0b1100_0001, 0x00];
        for _ in 1..15 {
            body.extend_from_slice(&[0x03, 0x00]);
        }
        body.extend_from_slice(&[0x01, 0x02]);
        let tree = read(&file(&header(19), &body)[..], LIMIT).unwrap();
        assert_eq!(tree.occupied, vec![VoxelKey::new(0, 0, -32767)]);
        assert_eq!(tree.stats.nodes, 19);
        assert_eq!(tree.stats.free_leaves, 2);
        assert_eq!(tree.stats.occupied_leaves, 1);
        assert_eq!(tree.stats.occupied_leaves_by_depth[16], 1);
    }

    fn assert_line_error(bytes: &[u8], line: usize, needle: &str) {
        match read(bytes, LIMIT) {
            Err(ParseError::Invalid {
                at: Location::Line(l),
                reason,
            }) => {
                assert_eq!(l, line, "{reason}");
                assert!(reason.contains(needle), "{reason}");
            }
            other => panic!("expected a line {line} error, got {other:?}"),
        }
    }

    #[test]
    fn header_errors() {
        assert!(matches!(read(&b""[..], LIMIT), Err(ParseError::Empty)));
        assert_line_error(b"ply\n", 1, "# Octomap OcTree binary file");
        assert!(matches!(
            read(&b"# Octomap OcTree file\nid OcTree\n"[..], LIMIT),
            Err(ParseError::Unsupported(m)) if m.contains(".ot")
        ));
        assert!(matches!(
            read(&b"# Octomap OcTree binary file\nid OcTree\nsize 0\nres 0.1\n"[..], LIMIT),
            Err(ParseError::Truncated(m)) if m.contains("data")
        ));
        let h = "# Octomap OcTree binary file\n# c\n";
        let bad = |rest: &str| format!("{h}{rest}").into_bytes();
        assert_line_error(&bad("id ColorOcTree\nsize 0\nres 0.1\ndata\n"), 3, "OcTree");
        assert_line_error(
            &bad("id\nsize 0\nres 0.1\ndata\n"),
            3,
            "'id' without a value",
        );
        assert_line_error(&bad("id OcTree\nsize x\nres 0.1\ndata\n"), 4, "'size x'");
        assert_line_error(&bad("id OcTree\nsize -1\nres 0.1\ndata\n"), 4, "size");
        for r in ["abc", "0", "-0.1", "nan", "inf", "0.1 0.2"] {
            assert_line_error(
                &bad(&format!("id OcTree\nsize 0\nres {r}\ndata\n")),
                5,
                "res",
            );
        }
        assert_line_error(&bad("id OcTree\nres 0.1\ndata\n"), 5, "size");
        assert_line_error(&bad("size 0\nres 0.1\ndata\n"), 5, "id");
        assert_line_error(&bad("id OcTree\nsize 0\ndata\n"), 5, "res");
        assert_line_error(&bad("id OcTree\nid OcTree\n"), 4, "second 'id'");
        assert_line_error(&bad("id OcTree\nsize 0\nres 0.1\ndata 5\n"), 6, "data");
        assert_line_error(
            &bad("id OcTree\nvalue 3\n"),
            4,
            "unknown header keyword 'value'",
        );
        let mut long = h.as_bytes().to_vec();
        long.extend(std::iter::repeat_n(b'a', 70_000));
        assert_line_error(&long, 3, "longer than");
    }

    #[test]
    fn crlf_header_and_comments_are_accepted() {
        let (bytes, _) = written(0.1, &[VoxelKey::new(5, 6, 7)]);
        let body = body_of(&bytes).to_vec();
        let text = "# Octomap OcTree binary file\r\n# a comment\r\n\r\n  # indented\r\nres 0.1\r\n\
                    size 17\r\nid OcTree\r\ndata\r\n";
        let tree = read(&file(text, &body)[..], LIMIT).unwrap();
        assert_eq!(tree.occupied, vec![VoxelKey::new(5, 6, 7)]);
    }

    #[test]
    fn body_errors() {
        let keys = block(VoxelKey::new(1, 1, 1), 3);
        let (bytes, stats) = written(0.1, &keys);
        let body = body_of(&bytes).to_vec();
        let n = stats.nodes;
        assert!(read(&file(&header(n), &body)[..], LIMIT).is_ok());

        // `size` too large and too small.
        let e = read(&file(&header(n + 1), &body)[..], LIMIT).unwrap_err();
        assert!(
            matches!(&e, ParseError::Malformed(m) if m.contains(&format!("size {}", n + 1))),
            "{e}"
        );
        let e = read(&file(&header(n - 1), &body)[..], LIMIT).unwrap_err();
        assert!(
            matches!(&e, ParseError::Invalid { at: Location::Byte(_), reason } if reason.contains("more nodes")),
            "{e}"
        );
        let e = read(&file(&header(1_000_000_000_000), &body)[..], LIMIT).unwrap_err();
        assert!(matches!(&e, ParseError::Malformed(_)), "{e}");
        let e = read(&file(&header(1_000_000_000_000), &[0xFF, 0xFF])[..], LIMIT).unwrap_err();
        assert!(matches!(&e, ParseError::Truncated(_)), "{e}");

        // Trailing bytes.
        let mut long = body.clone();
        long.extend_from_slice(&[1, 2, 3]);
        let e = read(&file(&header(n), &long)[..], LIMIT).unwrap_err();
        assert!(
            matches!(&e, ParseError::Malformed(m) if m.contains("3 bytes remain")),
            "{e}"
        );
        let e = read(&file(&header(0), &[0])[..], LIMIT).unwrap_err();
        assert!(
            matches!(&e, ParseError::Malformed(m) if m.contains("1 bytes follow")),
            "{e}"
        );

        // Cut short anywhere, including inside a node's two bytes.
        for cut in 0..body.len() {
            let e = read(&file(&header(n), &body[..cut])[..], LIMIT).unwrap_err();
            assert!(matches!(&e, ParseError::Truncated(_)), "cut {cut}: {e}");
        }

        // An inner node below depth 15.
        let mut deep = Vec::new();
        for _ in 0..16 {
            deep.extend_from_slice(&[0x03, 0x00]);
        }
        let e = read(&file(&header(100), &deep)[..], LIMIT).unwrap_err();
        assert!(
            matches!(&e, ParseError::Invalid { at: Location::Byte(b), reason }
                if *b == header(100).len() as u64 + 30 && reason.contains("depth 16")),
            "{e}"
        );
    }

    /// Applies (kind, position, byte) edits: flip, insert, delete, truncate.
    fn mutate(bytes: &mut Vec<u8>, ops: &[(u8, usize, u8)]) {
        for &(kind, pos, b) in ops {
            let len = bytes.len();
            match kind {
                0 if len > 0 => bytes[pos % len] ^= b | 1,
                1 => bytes.insert(pos % (len + 1), b),
                2 if len > 0 => {
                    bytes.remove(pos % len);
                }
                3 => bytes.truncate(pos % (len + 1)),
                _ => {}
            }
        }
    }

    fn seeds() -> Vec<Vec<u8>> {
        let mut mixed: Vec<VoxelKey> = (0..40)
            .map(|i| VoxelKey::new(i % 7 - 3, i % 5 - 2, i % 3 - 1))
            .collect();
        mixed.extend(block(VoxelKey::new(4, 4, -8), 4));
        vec![
            written(0.1, &[VoxelKey::new(0, 0, 0)]).0,
            written(0.1, &block(VoxelKey::new(-2, 0, 2), 2)).0,
            written(0.05, &mixed).0,
            written(0.1, &[]).0,
        ]
    }

    fn key_in(range: std::ops::Range<i32>) -> impl Strategy<Value = VoxelKey> {
        (range.clone(), range.clone(), range).prop_map(|(x, y, z)| VoxelKey::new(x, y, z))
    }

    proptest! {
        #[test]
        fn round_trip_small_cube(
            keys in prop::collection::vec(key_in(-20..20), 0..300),
            blocks in prop::collection::vec((key_in(-5..5), prop::bool::ANY), 0..4),
        ) {
            let mut all = keys;
            for (corner, big) in blocks {
                let edge = if big { 4 } else { 2 };
                let origin = VoxelKey::new(corner.x * edge, corner.y * edge, corner.z * edge);
                all.extend(block(origin, edge));
            }
            let (bytes, stats) = written(0.1, &all);
            let tree = read(&bytes[..], LIMIT).unwrap();
            let expected = sorted_set(&all);
            prop_assert!(stats.occupied_leaves <= expected.len() as u64);
            prop_assert_eq!(&tree.occupied, &expected);
            prop_assert_eq!(&tree.stats, &stats);
        }

        #[test]
        fn round_trip_full_key_range(
            keys in prop::collection::vec(
                (any::<i16>(), any::<i16>(), any::<i16>())
                    .prop_map(|(x, y, z)| VoxelKey::new(x.into(), y.into(), z.into())),
                0..60,
            ),
        ) {
            let (bytes, stats) = written(0.3, &keys);
            let tree = read(&bytes[..], LIMIT).unwrap();
            prop_assert_eq!(tree.occupied, sorted_set(&keys));
            prop_assert_eq!(tree.stats, stats);
        }

        #[test]
        fn mutated_files_never_panic(
            seed in 0usize..4,
            ops in prop::collection::vec((0u8..4, any::<usize>(), any::<u8>()), 1..6),
        ) {
            let mut bytes = seeds()[seed].clone();
            mutate(&mut bytes, &ops);
            if let Ok(tree) = read(&bytes[..], LIMIT) {
                prop_assert!(tree.occupied.windows(2).all(|w| w[0] < w[1]));
            }
        }

        #[test]
        fn random_bodies_never_panic(
            size in prop_oneof![0u64..200, any::<u64>()],
            body in prop::collection::vec(any::<u8>(), 0..300),
        ) {
            let _ = read(&file(&header(size), &body)[..], LIMIT);
        }
    }
}
