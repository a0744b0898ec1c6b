//! Triangles into pixels: perspective projection, a z-buffer on inverse depth (exact under
//! perspective), flat Lambert shading from one light, both faces lit (descriptions' meshes
//! come with either winding).

use super::Camera;
use super::mesh::{Triangle, cross, normalize};

/// Background colour (light grey).
pub const BACKGROUND: [u8; 3] = [236, 238, 242];
/// Nearest depth drawn (metres); a triangle reaching closer is skipped.
const NEAR: f32 = 0.01;
/// Share of a colour lit regardless of the light.
const AMBIENT: f32 = 0.35;

/// An RGB image, rows top to bottom, 3 bytes a pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Frame {
    /// The pixel at (`x`, `y`); panics outside the frame.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    pub(super) fn pixel_mut(&mut self, x: i32, y: i32) -> &mut [u8] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        &mut self.rgb[i..i + 3]
    }
}

/// A camera's frame of reference: where a world point lands on the screen.
pub(super) struct View {
    eye: [f32; 3],
    right: [f32; 3],
    up: [f32; 3],
    forward: [f32; 3],
    focal: f32,
    width: f32,
    height: f32,
}

impl View {
    pub fn new(camera: &Camera) -> Self {
        let forward = normalize([
            camera.target[0] - camera.eye[0],
            camera.target[1] - camera.eye[1],
            camera.target[2] - camera.eye[2],
        ]);
        let mut right = cross(forward, [0.0, 0.0, 1.0]);
        if dot(right, right) < 1e-12 {
            right = [1.0, 0.0, 0.0];
        }
        let right = normalize(right);
        let half_fov = camera.fov_y_deg.clamp(1.0, 170.0).to_radians() / 2.0;
        let height = camera.height.max(1) as f32;
        View {
            eye: camera.eye,
            right,
            up: cross(right, forward),
            forward,
            focal: height / 2.0 / half_fov.tan(),
            width: camera.width.max(1) as f32,
            height,
        }
    }

    /// Screen x, y and inverse depth of world point `p`; none behind the near plane.
    pub fn project(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        let d = [p[0] - self.eye[0], p[1] - self.eye[1], p[2] - self.eye[2]];
        let z = dot(d, self.forward);
        if z < NEAR {
            return None;
        }
        Some([
            self.width / 2.0 + dot(d, self.right) / z * self.focal,
            self.height / 2.0 - dot(d, self.up) / z * self.focal,
            1.0 / z,
        ])
    }
}

pub(super) struct Raster {
    frame: Frame,
    /// 1 / depth of the nearest surface drawn at each pixel (0: none).
    inverse_depth: Vec<f32>,
    view: View,
    light: [f32; 3],
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Raster {
    pub fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width.max(1), camera.height.max(1));
        let view = View::new(camera);
        let (right, up, forward) = (view.right, view.up, view.forward);
        Raster {
            frame: Frame {
                width: w,
                height: h,
                rgb: BACKGROUND.repeat((w * h) as usize),
            },
            inverse_depth: vec![0.0; (w * h) as usize],
            view,
            // From above, behind the camera's right shoulder.
            light: normalize([
                right[0] + 2.0 * up[0] - 1.5 * forward[0],
                right[1] + 2.0 * up[1] - 1.5 * forward[1],
                right[2] + 2.0 * up[2] - 1.5 * forward[2],
            ]),
        }
    }

    pub fn triangles(&mut self, triangles: &[Triangle], color: [u8; 3]) {
        for t in triangles {
            self.triangle(t, color);
        }
    }

    fn triangle(&mut self, t: &Triangle, color: [u8; 3]) {
        let v = &self.view;
        let (Some(a), Some(b), Some(c)) = (v.project(t[0]), v.project(t[1]), v.project(t[2]))
        else {
            return;
        };
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if area.abs() < 1e-12 {
            return;
        }
        let e1 = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
        let e2 = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
        let normal = normalize(cross(e1, e2));
        let shade = AMBIENT + (1.0 - AMBIENT) * dot(normal, self.light).abs();
        let shaded = color.map(|c| (c as f32 * shade).round().clamp(0.0, 255.0) as u8);
        let (w, h) = (self.frame.width as i32, self.frame.height as i32);
        let x0 = (a[0].min(b[0]).min(c[0]).floor() as i32).max(0);
        let x1 = (a[0].max(b[0]).max(c[0]).ceil() as i32).min(w - 1);
        let y0 = (a[1].min(b[1]).min(c[1]).floor() as i32).max(0);
        let y1 = (a[1].max(b[1]).max(c[1]).ceil() as i32).min(h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                // Pixel centre's barycentric weights.
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let wa = ((b[0] - px) * (c[1] - py) - (b[1] - py) * (c[0] - px)) / area;
                let wb = ((c[0] - px) * (a[1] - py) - (c[1] - py) * (a[0] - px)) / area;
                let wc = 1.0 - wa - wb;
                if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                    continue;
                }
                let inverse = wa * a[2] + wb * b[2] + wc * c[2];
                let i = (y * w + x) as usize;
                if inverse > self.inverse_depth[i] {
                    self.inverse_depth[i] = inverse;
                    self.frame.rgb[3 * i..3 * i + 3].copy_from_slice(&shaded);
                }
            }
        }
    }

    pub fn finish(self) -> Frame {
        self.frame
    }
}
