//! Line plots as PNG images (joint error against frame, the ablation): axes with ticks, one
//! polyline per series, a legend, and text in a built-in 5x7 pixel font, so that plotting
//! needs no font files on the machine.

use image::{Rgb, RgbImage};

/// One series: name, colour, points (x, y).
pub struct Series {
    pub name: String,
    pub colour: [u8; 3],
    pub points: Vec<(f64, f64)>,
}

/// A line plot.
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Dashed horizontal reference lines: (y, label).
    pub references: Vec<(f64, String)>,
}

/// Distinct colours for series.
pub const COLOURS: [[u8; 3]; 6] = [
    [214, 39, 40],
    [31, 119, 180],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [90, 90, 90],
];

const W: u32 = 960;
const H: u32 = 540;
const LEFT: i64 = 80;
const RIGHT: i64 = 200;
const TOP: i64 = 50;
const BOTTOM: i64 = 60;
const SCALE: i64 = 2;

/// 5x7 glyphs, one string of 7 rows of 5 bits (as '#' and '.') per character.
fn glyph(c: char) -> Option<[u8; 7]> {
    let rows: &str = match c.to_ascii_uppercase() {
        '0' => ".###.#...##..###.#.###..##...#.###.",
        '1' => "..#...##....#....#....#....#...###.",
        '2' => ".###.#...#....#...#...#...#...#####",
        '3' => "####.....#...#..##......##...#.###.",
        '4' => "...#...##..#.#.#..#.#####...#....#.",
        '5' => "######....####.....#....##...#.###.",
        '6' => "..##..#...#....####.#...##...#.###.",
        '7' => "#####....#...#...#...#....#....#...",
        '8' => ".###.#...##...#.###.#...##...#.###.",
        '9' => ".###.#...##...#.####....#...#..##..",
        'A' => ".###.#...##...#######...##...##...#",
        'B' => "####.#...##...#####.#...##...#####.",
        'C' => ".###.#...##....#....#....#...#.###.",
        'D' => "###..#..#.#...##...##...##..#.###..",
        'E' => "######....#....####.#....#....#####",
        'F' => "######....#....####.#....#....#....",
        'G' => ".###.#...##....#.####...##...#.####",
        'H' => "#...##...##...#######...##...##...#",
        'I' => ".###...#....#....#....#....#...###.",
        'J' => "..###...#....#....#....##..#..##...",
        'K' => "#...##..#.#.#..##...#.#..#..#.#...#",
        'L' => "#....#....#....#....#....#....#####",
        'M' => "#...###.###.#.##...##...##...##...#",
        'N' => "#...###..##.#.##..###...##...##...#",
        'O' => ".###.#...##...##...##...##...#.###.",
        'P' => "####.#...##...#####.#....#....#....",
        'Q' => ".###.#...##...##...##.#.##..#..##.#",
        'R' => "####.#...##...#####.#.#..#..#.#...#",
        'S' => ".#####....#.....###.....#....#####.",
        'T' => "#####..#....#....#....#....#....#..",
        'U' => "#...##...##...##...##...##...#.###.",
        'V' => "#...##...##...##...##...#.#.#...#..",
        'W' => "#...##...##...##.#.##.#.##.#.#.#.#.",
        'X' => "#...##...#.#.#...#...#.#.#...##...#",
        'Y' => "#...##...#.#.#...#....#....#....#..",
        'Z' => "#####....#...#...#...#...#....#####",
        '.' => "..........................##...##..",
        ',' => ".....................##...##...#...",
        '-' => "...............###.................",
        '+' => ".......#....#..#####..#....#.......",
        ':' => ".....##...##.........##...##.......",
        '(' => "...#...#...#....#....#.....#.....#.",
        ')' => ".#.....#.....#....#....#...#...#...",
        '_' => "..............................#####",
        '/' => ".........#...#...#...#...#.........",
        '=' => "..........#####.....#####..........",
        '<' => "...#...#...#...#.....#.....#.....#.",
        ' ' => "...................................",
        _ => return None,
    };
    let b = rows.as_bytes();
    let mut out = [0u8; 7];
    for (r, row) in out.iter_mut().enumerate() {
        for k in 0..5 {
            if b.get(r * 5 + k) == Some(&b'#') {
                *row |= 1 << (4 - k);
            }
        }
    }
    Some(out)
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, Rgb(c));
    }
}

/// Text with its top-left corner at (x, y); `SCALE` pixels per font pixel.
pub(crate) fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, c: [u8; 3]) {
    for (i, ch) in s.chars().enumerate() {
        let g = glyph(ch).unwrap_or_else(|| glyph('_').expect("glyph"));
        for (r, row) in g.iter().enumerate() {
            for k in 0..5 {
                if row & (1 << (4 - k)) != 0 {
                    for dy in 0..SCALE {
                        for dx in 0..SCALE {
                            put(
                                img,
                                x + (i as i64 * 6 + k) * SCALE + dx,
                                y + r as i64 * SCALE + dy,
                                c,
                            );
                        }
                    }
                }
            }
        }
    }
}

fn text_width(s: &str) -> i64 {
    s.chars().count() as i64 * 6 * SCALE
}

/// A line of width 2 from a to b, every `dash` pixels on and off when dashed.
fn line(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), c: [u8; 3], dash: Option<usize>) {
    let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        if dash.is_some_and(|d| (i / d) % 2 == 1) {
            continue;
        }
        let t = i as f64 / n as f64;
        let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            put(img, x.round() as i64 + dx, y.round() as i64 + dy, c);
        }
    }
}

/// A "nice" tick step for a range.
fn tick_step(range: f64) -> f64 {
    let raw = range / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

impl LinePlot {
    /// Draws the plot. Non-finite points are skipped.
    pub fn render(&self) -> RgbImage {
        let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
        let pts = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|p| p.0.is_finite() && p.1.is_finite())
        };
        let (mut x0, mut x1) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
            (a.0.min(p.0), a.1.max(p.0))
        });
        let mut y1 = pts().fold(0.0f64, |a, p| a.max(p.1));
        for (y, _) in &self.references {
            y1 = y1.max(*y);
        }
        if !x0.is_finite() {
            (x0, x1) = (0.0, 1.0);
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let y0 = 0.0;
        let ystep = tick_step((y1 - y0).max(1e-9) * 1.05);
        let y1 = ((y1 * 1.05) / ystep).ceil().max(1.0) * ystep;
        let (pw, ph) = (
            (W as i64 - LEFT - RIGHT) as f64,
            (H as i64 - TOP - BOTTOM) as f64,
        );
        let px = |x: f64| LEFT as f64 + (x - x0) / (x1 - x0) * pw;
        let py = |y: f64| TOP as f64 + (1.0 - (y - y0) / (y1 - y0)) * ph;
        let grey = [200, 200, 200];
        let black = [0, 0, 0];
        // Grid and ticks.
        let mut y = y0;
        while y <= y1 + 1e-9 {
            line(&mut img, (px(x0), py(y)), (px(x1), py(y)), grey, None);
            let label = format!("{}", (y * 1000.0).round() / 1000.0);
            text(
                &mut img,
                LEFT - 8 - text_width(&label),
                py(y).round() as i64 - 7,
                &label,
                black,
            );
            y += ystep;
        }
        let xstep = tick_step(x1 - x0).max(1.0);
        let mut x = (x0 / xstep).ceil() * xstep;
        while x <= x1 + 1e-9 {
            line(
                &mut img,
                (px(x), py(y0)),
                (px(x), py(y0) + 6.0),
                black,
                None,
            );
            let label = format!("{x}");
            text(
                &mut img,
                px(x).round() as i64 - text_width(&label) / 2,
                py(y0) as i64 + 10,
                &label,
                black,
            );
            x += xstep;
        }
        line(&mut img, (px(x0), py(y0)), (px(x1), py(y0)), black, None);
        line(&mut img, (px(x0), py(y0)), (px(x0), py(y1)), black, None);
        for (y, label) in &self.references {
            line(
                &mut img,
                (px(x0), py(*y)),
                (px(x1), py(*y)),
                [120, 120, 120],
                Some(8),
            );
            text(
                &mut img,
                px(x1) as i64 + 8,
                py(*y) as i64 - 7,
                label,
                [120, 120, 120],
            );
        }
        for s in &self.series {
            let p: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .map(|&(x, y)| (px(x), py(y.min(y1))))
                .collect();
            for w in p.windows(2) {
                line(&mut img, w[0], w[1], s.colour, None);
            }
            for &(x, y) in &p {
                for dy in -3..=3 {
                    for dx in -3..=3 {
                        put(
                            &mut img,
                            x.round() as i64 + dx,
                            y.round() as i64 + dy,
                            s.colour,
                        );
                    }
                }
            }
        }
        // Legend, title and axis labels.
        for (i, s) in self.series.iter().enumerate() {
            let y = TOP + 10 + i as i64 * 24;
            let x = W as i64 - RIGHT + 20;
            line(
                &mut img,
                (x as f64, y as f64 + 6.0),
                (x as f64 + 24.0, y as f64 + 6.0),
                s.colour,
                None,
            );
            text(&mut img, x + 32, y, &s.name, black);
        }
        text(
            &mut img,
            (W as i64 - text_width(&self.title)) / 2,
            14,
            &self.title,
            black,
        );
        text(
            &mut img,
            LEFT + (pw as i64 - text_width(&self.x_label)) / 2,
            H as i64 - 24,
            &self.x_label,
            black,
        );
        text(&mut img, 8, TOP - 30, &self.y_label, black);
        img
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_glyph_has_35_cells_and_series_are_drawn() {
        for c in "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.,-+:()_/=< ".chars() {
            let g = glyph(c).unwrap();
            assert!(g.iter().all(|r| *r < 32));
        }
        let plot = LinePlot {
            title: "t".into(),
            x_label: "frame".into(),
            y_label: "cm".into(),
            series: vec![Series {
                name: "a".into(),
                colour: COLOURS[0],
                points: vec![(0.0, 1.0), (10.0, 2.0), (11.0, f64::NAN)],
            }],
            references: vec![(1.0, "1 cm".into())],
        };
        let img = plot.render();
        let red = img.pixels().filter(|p| p.0 == COLOURS[0]).count();
        assert!(red > 300, "{red} series pixels");
    }
}
