//! For every pixel of a silhouette, the nearest silhouette pixel: where the tracked
//! surface's vertices that project outside a camera's mask are pulled back to.

use image::GrayImage;

/// A mask's nearest-silhouette-pixel field: two raster scans that pass each pixel's
/// nearest silhouette pixel on to its neighbours (Danielsson's vector propagation; within
/// a pixel of the exact Euclidean nearest).
pub struct NearestInside {
    width: u32,
    height: u32,
    /// Per pixel, the index (y * width + x) of the nearest silhouette pixel; `u32::MAX`
    /// when the mask is empty.
    nearest: Vec<u32>,
    /// The silhouette's outline: its pixels with a 4-neighbour outside it (not counting the
    /// image's border, where the subject leaves the view), (x, y).
    pub contour: Vec<(u32, u32)>,
}

/// A mask value above this is silhouette.
const INSIDE: u8 = 127;

impl NearestInside {
    pub fn new(mask: &GrayImage) -> NearestInside {
        let (w, h) = mask.dimensions();
        let (wi, hi) = (w as i64, h as i64);
        let mut nearest: Vec<u32> = mask
            .as_raw()
            .iter()
            .enumerate()
            .map(|(i, &v)| if v > INSIDE { i as u32 } else { u32::MAX })
            .collect();
        let d2 = |x: i64, y: i64, s: u32| -> i64 {
            if s == u32::MAX {
                return i64::MAX;
            }
            let (sx, sy) = ((s % w) as i64, (s / w) as i64);
            (sx - x) * (sx - x) + (sy - y) * (sy - y)
        };
        let offer = |nearest: &mut Vec<u32>, x: i64, y: i64, nx: i64, ny: i64| {
            if nx < 0 || ny < 0 || nx >= wi || ny >= hi {
                return;
            }
            let here = (y * wi + x) as usize;
            let candidate = nearest[(ny * wi + nx) as usize];
            if d2(x, y, candidate) < d2(x, y, nearest[here]) {
                nearest[here] = candidate;
            }
        };
        for y in 0..hi {
            for x in 0..wi {
                for (dx, dy) in [(-1, 0), (-1, -1), (0, -1), (1, -1)] {
                    offer(&mut nearest, x, y, x + dx, y + dy);
                }
            }
            for x in (0..wi).rev() {
                offer(&mut nearest, x, y, x + 1, y);
            }
        }
        for y in (0..hi).rev() {
            for x in (0..wi).rev() {
                for (dx, dy) in [(1, 0), (1, 1), (0, 1), (-1, 1)] {
                    offer(&mut nearest, x, y, x + dx, y + dy);
                }
            }
            for x in 0..wi {
                offer(&mut nearest, x, y, x - 1, y);
            }
        }
        let inside = |x: i64, y: i64| mask.get_pixel(x as u32, y as u32)[0] > INSIDE;
        let contour = (0..hi)
            .flat_map(|y| (0..wi).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                inside(x, y)
                    && [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|(dx, dy)| {
                        let (nx, ny) = (x + dx, y + dy);
                        nx >= 0 && ny >= 0 && nx < wi && ny < hi && !inside(nx, ny)
                    })
            })
            .map(|(x, y)| (x as u32, y as u32))
            .collect();
        NearestInside {
            width: w,
            height: h,
            nearest,
            contour,
        }
    }

    /// The nearest silhouette pixel (x, y) to pixel (x, y), itself inside the silhouette;
    /// `None` outside the image or for an empty mask.
    pub fn nearest(&self, x: i64, y: i64) -> Option<(u32, u32)> {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        let s = self.nearest[(y * self.width as i64 + x) as usize];
        (s != u32::MAX).then(|| (s % self.width, s / self.width))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a brute-force search on a mask with two blobs: every pixel's nearest
    /// silhouette pixel is within 1 px of the true nearest distance.
    #[test]
    fn nearest_silhouette_pixels_match_a_brute_force_search() {
        let (w, h) = (60u32, 40u32);
        let mask = GrayImage::from_fn(w, h, |x, y| {
            let a = (x as i64 - 15).pow(2) + (y as i64 - 20).pow(2) < 36;
            let b = (30..34).contains(&x) && (5..35).contains(&y);
            image::Luma([if a || b { 255 } else { 0 }])
        });
        let field = NearestInside::new(&mask);
        let inside: Vec<(i64, i64)> = (0..h as i64)
            .flat_map(|y| (0..w as i64).map(move |x| (x, y)))
            .filter(|&(x, y)| mask.get_pixel(x as u32, y as u32)[0] > 127)
            .collect();
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let best = inside
                    .iter()
                    .map(|&(sx, sy)| (((sx - x).pow(2) + (sy - y).pow(2)) as f64).sqrt())
                    .fold(f64::INFINITY, f64::min);
                let (sx, sy) = field.nearest(x, y).expect("mask not empty");
                assert!(mask.get_pixel(sx, sy)[0] > 127);
                let got = (((sx as i64 - x).pow(2) + (sy as i64 - y).pow(2)) as f64).sqrt();
                assert!(got <= best + 1.0, "pixel ({x}, {y}): {got} against {best}");
            }
        }
        assert_eq!(field.nearest(-1, 0), None);
        assert_eq!(field.nearest(15, 20), Some((15, 20)));
    }
}
