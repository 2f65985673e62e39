//! Texels no photo coloured: holes inside charts (surface no view sees) and the gutters
//! between charts, filled by push-pull (Gortler et al. 1996, "The Lumigraph", section 3.3):
//! known texels are averaged down a pyramid (2x2, weighted by how much of each block is
//! known), then every level's unknown part is filled from the level above, bilinearly, on
//! the way back up. Holes get a smooth continuation of the colours around them (never black),
//! and gutters the colours of the nearest charts, so that every mip level a viewer builds
//! averages chart colours with their own continuation, not with a background colour.

/// Fills, in place, the texels of `colour` whose `weight` is 0 (`width` x `height`,
/// row-major); `weight` in [0, 1]. With no known texel at all, everything is left as is.
pub fn push_pull(colour: &mut [[f32; 3]], weight: &[f32], width: usize, height: usize) {
    assert_eq!(colour.len(), width * height);
    assert_eq!(weight.len(), width * height);
    if width == 0 || height == 0 || weight.iter().all(|&w| w <= 0.0) {
        return;
    }
    // Push: premultiplied colours and weights, level by level.
    let mut levels: Vec<(usize, usize, Vec<[f32; 4]>)> = Vec::new();
    let base: Vec<[f32; 4]> = colour
        .iter()
        .zip(weight)
        .map(|(c, &w)| {
            let w = w.clamp(0.0, 1.0);
            [c[0] * w, c[1] * w, c[2] * w, w]
        })
        .collect();
    levels.push((width, height, base));
    while {
        let (w, h, _) = levels.last().expect("a level");
        *w > 1 || *h > 1
    } {
        let (w, h, prev) = levels.last().expect("a level");
        let (w, h) = (*w, *h);
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        let mut next = vec![[0f32; 4]; nw * nh];
        for y in 0..nh {
            for x in 0..nw {
                let mut s = [0f32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (2 * x + dx, 2 * y + dy);
                    if sx < w && sy < h {
                        let p = prev[sy * w + sx];
                        for k in 0..4 {
                            s[k] += p[k];
                        }
                    }
                }
                // Normalise the weight to [0, 1] while keeping colour / weight.
                if s[3] > 1.0 {
                    let f = 1.0 / s[3];
                    s = s.map(|v| v * f);
                }
                next[y * nw + x] = s;
            }
        }
        levels.push((nw, nh, next));
    }
    // Pull: fill each level's missing weight from the (already filled) level above.
    for l in (0..levels.len() - 1).rev() {
        let (upper, lower) = levels.split_at_mut(l + 1);
        let (w, h, cur) = &mut upper[l];
        let (pw, ph, parent) = &lower[0];
        for y in 0..*h {
            for x in 0..*w {
                let i = y * *w + x;
                let wgt = cur[i][3];
                if wgt >= 1.0 {
                    continue;
                }
                // Bilinear lookup of the parent at this texel's centre.
                let px = ((x as f32 + 0.5) / 2.0 - 0.5).clamp(0.0, (*pw - 1) as f32);
                let py = ((y as f32 + 0.5) / 2.0 - 0.5).clamp(0.0, (*ph - 1) as f32);
                let (x0, y0) = (px.floor() as usize, py.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(*pw - 1), (y0 + 1).min(*ph - 1));
                let (ax, ay) = (px - x0 as f32, py - y0 as f32);
                let mut up = [0f32; 3];
                for k in 0..3 {
                    let get = |xx: usize, yy: usize| {
                        let p = parent[yy * *pw + xx];
                        if p[3] > 0.0 { p[k] / p[3] } else { 0.0 }
                    };
                    up[k] = (get(x0, y0) * (1.0 - ax) + get(x1, y0) * ax) * (1.0 - ay)
                        + (get(x0, y1) * (1.0 - ax) + get(x1, y1) * ax) * ay;
                }
                for k in 0..3 {
                    cur[i][k] += (1.0 - wgt) * up[k];
                }
                cur[i][3] = 1.0;
            }
        }
    }
    for (c, p) in colour.iter_mut().zip(&levels[0].2) {
        if p[3] > 0.0 {
            *c = [p[0] / p[3], p[1] / p[3], p[2] / p[3]];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_texels_stay_and_holes_take_their_neighbours_colour() {
        let (w, h) = (16, 16);
        let mut colour = vec![[0f32; 3]; w * h];
        let mut weight = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                if x < 6 {
                    colour[y * w + x] = [1.0, 0.5, 0.25];
                    weight[y * w + x] = 1.0;
                }
            }
        }
        let before = colour.clone();
        push_pull(&mut colour, &weight, w, h);
        for i in 0..w * h {
            if weight[i] > 0.0 {
                assert_eq!(colour[i], before[i]);
            } else {
                // One colour known: every filled texel gets it.
                for k in 0..3 {
                    assert!(
                        (colour[i][k] - before[0][k]).abs() < 1e-5,
                        "{:?}",
                        colour[i]
                    );
                }
            }
        }
    }

    #[test]
    fn a_hole_between_two_colours_is_filled_between_them() {
        let (w, h) = (32, 4);
        let mut colour = vec![[0f32; 3]; w * h];
        let mut weight = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if x < 8 {
                    colour[i] = [0.0; 3];
                    weight[i] = 1.0;
                } else if x >= 24 {
                    colour[i] = [1.0; 3];
                    weight[i] = 1.0;
                }
            }
        }
        push_pull(&mut colour, &weight, w, h);
        let mid = colour[w + 16][0];
        assert!(mid > 0.1 && mid < 0.9, "{mid}");
        // Closer to the dark side is darker.
        assert!(colour[w + 10][0] < colour[w + 21][0]);
    }
}
