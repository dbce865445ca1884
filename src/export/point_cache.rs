//! Point caches: one mesh's vertex positions in every frame, for a rest mesh with the same
//! vertices in the same order (Blender's Mesh Cache modifier reads both formats; Houdini and
//! three.js read MDD).
//!
//! - **PC2** (little-endian): the 12 bytes `POINTCACHE2\0`, then i32 version 1, i32 point
//!   count, f32 start frame, f32 sampling (frames per sample), i32 sample count, then per
//!   sample every point's f32 x, y, z.
//! - **MDD** (big-endian): i32 frame count, i32 point count, one f32 time per frame
//!   (seconds), then per frame every point's f32 x, y, z.
//!
//! Sample k is the k-th exported frame: PC2's start frame is 0 with one frame per sample, so
//! that Blender's modifier (time mode "Frame", start 0) shows sample k at scene frame k;
//! MDD's times are k / frame rate.

/// The PC2 bytes of `frames` (each one position per point, the same count in all).
pub fn to_pc2(frames: &[Vec<[f32; 3]>]) -> Vec<u8> {
    let points = frames.first().map_or(0, Vec::len);
    let mut out = Vec::with_capacity(32 + frames.len() * points * 12);
    out.extend(b"POINTCACHE2\0");
    out.extend(1i32.to_le_bytes());
    out.extend((points as i32).to_le_bytes());
    out.extend(0f32.to_le_bytes());
    out.extend(1f32.to_le_bytes());
    out.extend((frames.len() as i32).to_le_bytes());
    push_points(&mut out, frames, f32::to_le_bytes);
    out
}

/// The MDD bytes of `frames` at `frame_rate` frames per second.
pub fn to_mdd(frames: &[Vec<[f32; 3]>], frame_rate: f64) -> Vec<u8> {
    let points = frames.first().map_or(0, Vec::len);
    let mut out = Vec::with_capacity(8 + frames.len() * (4 + points * 12));
    out.extend((frames.len() as i32).to_be_bytes());
    out.extend((points as i32).to_be_bytes());
    for k in 0..frames.len() {
        out.extend(((k as f64 / frame_rate) as f32).to_be_bytes());
    }
    push_points(&mut out, frames, f32::to_be_bytes);
    out
}

/// Appends every point of every frame as three f32 in the byte order `bytes` gives.
fn push_points(out: &mut Vec<u8>, frames: &[Vec<[f32; 3]>], bytes: fn(f32) -> [u8; 4]) {
    for frame in frames {
        for p in frame {
            for &c in p {
                out.extend(bytes(c));
            }
        }
    }
}

/// The largest point cache written, bytes: both formats count in signed 32-bit integers,
/// and readers load a cache whole.
pub const MAX_BYTES: usize = i32::MAX as usize;

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<Vec<[f32; 3]>> {
        (0..3)
            .map(|k| {
                (0..4)
                    .map(|i| [i as f32, k as f32 * 0.5, -(i as f32) * 0.25])
                    .collect()
            })
            .collect()
    }

    fn f32_at(bytes: &[u8], at: usize, big: bool) -> f32 {
        let b: [u8; 4] = bytes[at..at + 4].try_into().unwrap();
        if big {
            f32::from_be_bytes(b)
        } else {
            f32::from_le_bytes(b)
        }
    }

    /// Read back by the layout each format documents: header fields, then point i of
    /// sample k at its offset.
    #[test]
    fn pc2_and_mdd_hold_every_point_of_every_frame_where_readers_look() {
        let frames = frames();
        let pc2 = to_pc2(&frames);
        assert_eq!(&pc2[..12], b"POINTCACHE2\0");
        let i32_le = |at: usize| i32::from_le_bytes(pc2[at..at + 4].try_into().unwrap());
        assert_eq!((i32_le(12), i32_le(16), i32_le(28)), (1, 4, 3));
        assert_eq!(
            (f32_at(&pc2, 20, false), f32_at(&pc2, 24, false)),
            (0.0, 1.0)
        );
        assert_eq!(pc2.len(), 32 + 3 * 4 * 12);
        let mdd = to_mdd(&frames, 25.0);
        let i32_be = |at: usize| i32::from_be_bytes(mdd[at..at + 4].try_into().unwrap());
        assert_eq!((i32_be(0), i32_be(4)), (3, 4));
        assert_eq!(f32_at(&mdd, 8 + 2 * 4, true), 2.0 / 25.0);
        assert_eq!(mdd.len(), 8 + 3 * 4 + 3 * 4 * 12);
        for (k, frame) in frames.iter().enumerate() {
            for (i, p) in frame.iter().enumerate() {
                for (c, &value) in p.iter().enumerate() {
                    let at = (k * 4 + i) * 12 + c * 4;
                    assert_eq!(f32_at(&pc2, 32 + at, false), value);
                    assert_eq!(f32_at(&mdd, 8 + 3 * 4 + at, true), value);
                }
            }
        }
    }
}
