//! Occupancy lists on the wire: a cloud that is exactly the sorted centres of the occupied
//! voxels of a grid (what robots exchange, thesis §6.3.2) is sent as its voxel keys,
//! delta-coded as variable-length integers (about 2 bytes per voxel instead of 12), and
//! decoded back to the very same `f32` points.

use nalgebra::Point3;
use olmap::cloud::PointCloud;
use olmap::geometry::VoxelKey;

use super::Reader;

/// Keys are packed into 63 bits: 21 bits per axis, offset by 2^20 (±104 km at 0.1 m).
const AXIS_BITS: u32 = 21;
const OFFSET: i64 = 1 << (AXIS_BITS - 1);
const AXIS_MASK: u64 = (1 << AXIS_BITS) - 1;
/// Most voxels one list may announce.
pub const MAX_VOXELS: usize = 16 << 20;

fn pack(k: &VoxelKey) -> Option<u64> {
    let f = |c: i32| {
        let v = c as i64 + OFFSET;
        (0..(1i64 << AXIS_BITS)).contains(&v).then_some(v as u64)
    };
    Some((f(k.x)? << (2 * AXIS_BITS)) | (f(k.y)? << AXIS_BITS) | f(k.z)?)
}

fn unpack(p: u64) -> VoxelKey {
    let f = |v: u64| ((v & AXIS_MASK) as i64 - OFFSET) as i32;
    VoxelKey::new(f(p >> (2 * AXIS_BITS)), f(p >> AXIS_BITS), f(p))
}

/// The point a voxel key stands for: its centre, as `f32`.
fn centre(k: &VoxelKey, resolution: f64) -> Point3<f32> {
    k.center(resolution).cast::<f32>()
}

/// The occupancy list of `cloud` at `resolution`: one point per occupied voxel, its centre,
/// in key order; the origin kept, attributes dropped.
pub fn occupancy_list(cloud: &PointCloud, resolution: f64) -> Option<PointCloud> {
    if !(resolution.is_finite() && resolution > 0.0) {
        return None;
    }
    let mut keys: Vec<u64> = cloud
        .points()
        .iter()
        .map(|p| VoxelKey::from_point(&p.cast::<f64>(), resolution).and_then(|k| pack(&k)))
        .collect::<Option<Vec<u64>>>()?;
    keys.sort_unstable();
    keys.dedup();
    let points = keys
        .iter()
        .map(|&k| centre(&unpack(k), resolution))
        .collect();
    Some(PointCloud::from_points(points).with_origin(cloud.origin()))
}

/// The packed keys of `cloud` if it is exactly an occupancy list at `resolution` (every
/// point bit-identical to its voxel's centre, strictly ascending keys, no attributes).
pub fn as_keys(cloud: &PointCloud, resolution: f64) -> Option<Vec<u64>> {
    if cloud.intensity().is_some() || cloud.normals().is_some() || cloud.colors().is_some() {
        return None;
    }
    let mut out = Vec::with_capacity(cloud.len());
    for p in cloud.points() {
        let k = VoxelKey::from_point(&p.cast::<f64>(), resolution)?;
        if centre(&k, resolution) != *p {
            return None;
        }
        let packed = pack(&k)?;
        if out.last().is_some_and(|&last| packed <= last) {
            return None;
        }
        out.push(packed);
    }
    Some(out)
}

/// Appends `keys` (strictly ascending) as a count and varint deltas.
pub fn put_keys(out: &mut Vec<u8>, keys: &[u64]) {
    out.extend_from_slice(&(keys.len() as u32).to_le_bytes());
    let mut prev = 0u64;
    for (i, &k) in keys.iter().enumerate() {
        let mut d = if i == 0 { k } else { k - prev };
        prev = k;
        loop {
            let byte = (d & 0x7f) as u8;
            d >>= 7;
            if d == 0 {
                out.push(byte);
                break;
            }
            out.push(byte | 0x80);
        }
    }
}

/// Reads keys written by [`put_keys`] and returns the cloud of their centres.
pub(crate) fn read_keys(r: &mut Reader<'_>, resolution: f64) -> Result<Vec<Point3<f32>>, String> {
    let n = r.count(1, MAX_VOXELS, "voxels")?;
    let mut points = Vec::with_capacity(n);
    let mut prev = 0u64;
    for i in 0..n {
        let mut d = 0u64;
        let mut shift = 0;
        loop {
            let b = r.take(1, "voxel key")?[0];
            if shift > 56 {
                return Err(format!("voxel {i}: key delta longer than 9 bytes"));
            }
            d |= ((b & 0x7f) as u64) << shift;
            shift += 7;
            if b & 0x80 == 0 {
                break;
            }
        }
        if i > 0 && d == 0 {
            return Err(format!("voxel {i}: repeated key"));
        }
        let k = prev
            .checked_add(d)
            .filter(|k| *k < 1 << (3 * AXIS_BITS))
            .ok_or_else(|| format!("voxel {i}: key out of range"))?;
        prev = k;
        points.push(centre(&unpack(k), resolution));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_occupancy_list_round_trips_bit_for_bit_in_about_two_bytes_per_voxel() {
        let mut pts = Vec::new();
        for i in 0..4000 {
            let a = i as f32 * 0.01;
            pts.push(Point3::new(
                5.0 * a.cos() - 1.3,
                4.0 * a.sin() + 0.7,
                0.1 + (i % 25) as f32 * 0.1,
            ));
        }
        let cloud = PointCloud::from_points(pts).with_origin(Point3::new(0.1, 0.2, 0.5));
        let list = occupancy_list(&cloud, 0.1).unwrap();
        let keys = as_keys(&list, 0.1).expect("an occupancy list is compact");
        let mut bytes = Vec::new();
        put_keys(&mut bytes, &keys);
        assert!(
            bytes.len() < 4 + 3 * keys.len(),
            "{} bytes for {} voxels",
            bytes.len(),
            keys.len()
        );
        let back = read_keys(&mut Reader::new(&bytes), 0.1).unwrap();
        assert_eq!(back, list.points());
        // A raw cloud is not an occupancy list.
        assert!(as_keys(&cloud, 0.1).is_none());
        // A damaged count or a cut stream is an error, not a huge allocation.
        let mut bad = bytes.clone();
        bad[3] = 0x7f;
        assert!(read_keys(&mut Reader::new(&bad), 0.1).is_err());
        assert!(read_keys(&mut Reader::new(&bytes[..bytes.len() - 1]), 0.1).is_err());
    }
}
