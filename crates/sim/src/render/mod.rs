//! A software renderer of the scene view ([`crate::view`]): every drawn part as flat-shaded
//! triangles through a pinhole camera into an RGB frame, with a z-buffer and one directional
//! light; captions in a 5 x 7 bitmap font. No display, no GPU: what the videos of episodes
//! (`crm record --video`, an evaluation's attached video) and the Python env's
//! `render_mode="rgb_array"` draw. Deterministic: the same parts and camera give the same
//! bytes.

mod font;
mod mesh;
mod raster;

pub use raster::Frame;

use crate::view::Part;

/// The colour a part is drawn in, by its name: the rerun recording's palette.
pub fn part_color(name: &str) -> [u8; 3] {
    if name == "table" {
        [150, 120, 90]
    } else if name.starts_with("object") {
        [70, 130, 200]
    } else if name == "hand/palm" {
        [210, 180, 150]
    } else {
        [230, 200, 170]
    }
}

/// Colour of the grasp location's marker (green, as in the rerun recording).
pub const GRASP_LOCATION_COLOR: [u8; 3] = [40, 180, 60];

/// A pinhole camera looking from `eye` at `target`, z up (the world's vertical).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

/// Frame size of videos and `rgb_array` unless asked otherwise (gymnasium's MuJoCo envs
/// render 480 x 480; a quarter of the pixels keeps a 1,000-frame GIF small).
pub const DEFAULT_SIZE: (u32, u32) = (320, 240);

impl Camera {
    /// A camera on `target` from `distance` metres to the front right and above, 45 degrees
    /// high.
    pub fn framing(target: [f32; 3], distance: f32, width: u32, height: u32) -> Self {
        let dir = mesh::normalize([0.75, -0.9, 0.65]);
        Camera {
            eye: [
                target[0] + dir[0] * distance,
                target[1] + dir[1] * distance,
                target[2] + dir[2] * distance,
            ],
            target,
            fov_y_deg: 45.0,
            width,
            height,
        }
    }

    /// A camera that shows the object and the hand of `parts`: on the midpoint of the
    /// object (its parts' mean position) and the palm, far enough back (at least 0.6 m) that
    /// both fit in the frame; on the object alone without a palm.
    pub fn on_scene(parts: &[Part], width: u32, height: u32) -> Self {
        let mean = |prefix: &str| {
            let chosen: Vec<&Part> = parts
                .iter()
                .filter(|p| p.name.starts_with(prefix))
                .collect();
            (!chosen.is_empty()).then(|| {
                let mut m = [0.0f32; 3];
                for p in &chosen {
                    for (t, x) in m.iter_mut().zip(p.translation) {
                        *t += x / chosen.len() as f32;
                    }
                }
                m
            })
        };
        let object = mean("object").unwrap_or([0.0; 3]);
        let Some(palm) = mean("hand/palm") else {
            return Camera::framing(object, 0.6, width, height);
        };
        let target = [
            (object[0] + palm[0]) / 2.0,
            (object[1] + palm[1]) / 2.0,
            (object[2] + palm[2]) / 2.0,
        ];
        let gap = ((palm[0] - object[0]).powi(2)
            + (palm[1] - object[1]).powi(2)
            + (palm[2] - object[2]).powi(2))
        .sqrt();
        // Half the frame's height spans tan(22.5 degrees) = 0.41 of the distance: the gap
        // with a hand's length to spare.
        Camera::framing(target, (1.6 * gap + 0.2).max(0.6), width, height)
    }
}

impl Camera {
    /// Where world point `p` lands in the frame (pixels from the top-left corner; may be
    /// outside it), or none behind the camera.
    pub fn project(&self, p: [f32; 3]) -> Option<[f32; 2]> {
        raster::View::new(self).project(p).map(|[x, y, _]| [x, y])
    }
}

/// Draws the parts a viewer draws (`Part::drawn`) and, when given, the grasp location as a
/// small green ball.
pub fn render(parts: &[Part], grasp_location: Option<[f32; 3]>, camera: &Camera) -> Frame {
    let mut frame = raster::Raster::new(camera);
    for part in parts.iter().filter(|p| p.drawn) {
        frame.triangles(&mesh::triangles(part), part_color(&part.name));
    }
    if let Some(at) = grasp_location {
        let marker = Part {
            name: "grasp_location".into(),
            shape: crate::view::PartShape::Ball { radius: 0.006 },
            translation: at,
            rotation: [0.0, 0.0, 0.0, 1.0],
            drawn: true,
        };
        frame.triangles(&mesh::triangles(&marker), GRASP_LOCATION_COLOR);
    }
    frame.finish()
}

impl Frame {
    /// Writes `lines` top-left over a dark band, each in its colour (2 x scale font).
    pub fn caption(&mut self, lines: &[(&str, [u8; 3])]) {
        if lines.is_empty() {
            return;
        }
        let scale = if self.width >= 480 { 2 } else { 1 };
        let line_h = 9 * scale as i32;
        let widest = lines
            .iter()
            .map(|(t, _)| t.chars().count())
            .max()
            .unwrap_or(0);
        let band_w = font::width(widest, scale) as i32 + 6;
        let band_h = line_h * lines.len() as i32 + 4;
        for y in 0..band_h.min(self.height as i32) {
            for x in 0..band_w.min(self.width as i32) {
                let px = self.pixel_mut(x, y);
                for c in px.iter_mut() {
                    *c /= 3;
                }
            }
        }
        for (k, (text, color)) in lines.iter().enumerate() {
            let y = 3 + k as i32 * line_h;
            font::draw(text, 3, y, scale, |x, y| {
                if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
                    self.pixel_mut(x, y).copy_from_slice(color);
                }
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::PartShape;

    fn cube(name: &str, at: [f32; 3], half: f32) -> Part {
        Part {
            name: name.into(),
            shape: PartShape::Cuboid {
                half_extents: [half; 3],
            },
            translation: at,
            rotation: [0.0, 0.0, 0.0, 1.0],
            drawn: true,
        }
    }

    #[test]
    fn an_object_in_front_of_the_camera_fills_the_frame_centre_in_its_colour() {
        let parts = [cube("object/part_0", [0.0; 3], 0.05)];
        let camera = Camera::on_scene(&parts, 64, 48);
        let frame = render(&parts, None, &camera);
        let [r, g, b] = frame.pixel(32, 24);
        // Shaded blue: the object's hue, darker or as bright.
        assert!(b > r && b > g && b <= 200, "{r} {g} {b}");
        // A corner is background.
        assert_eq!(frame.pixel(0, 0), raster::BACKGROUND);
    }

    #[test]
    fn the_nearer_part_hides_the_farther() {
        let object = cube("object/part_0", [0.0; 3], 0.05);
        let camera = Camera::framing([0.0; 3], 0.6, 64, 48);
        // The palm between the camera and the object, on the line of sight.
        let between = [
            camera.eye[0] * 0.5,
            camera.eye[1] * 0.5,
            camera.eye[2] * 0.5,
        ];
        let palm = cube("hand/palm", between, 0.02);
        for parts in [[object.clone(), palm.clone()], [palm, object]] {
            let [r, _, b] = render(&parts, None, &camera).pixel(32, 24);
            assert!(r > b, "the palm's colour, whichever is drawn first");
        }
    }

    #[test]
    fn a_part_not_drawn_leaves_no_pixel_and_the_same_input_gives_the_same_bytes() {
        let mut hidden = cube("object/part_0", [0.0; 3], 0.05);
        hidden.drawn = false;
        let camera = Camera::framing([0.0; 3], 0.6, 32, 24);
        let frame = render(&[hidden], None, &camera);
        assert!(frame.rgb.chunks(3).all(|p| p == raster::BACKGROUND));
        let parts = [cube("object/part_0", [0.0; 3], 0.05)];
        assert_eq!(
            render(&parts, Some([0.0; 3]), &camera).rgb,
            render(&parts, Some([0.0; 3]), &camera).rgb
        );
    }

    #[test]
    fn a_caption_writes_its_colour_over_a_darkened_band() {
        let camera = Camera::framing([0.0; 3], 0.6, 64, 48);
        let mut frame = render(&[], None, &camera);
        frame.caption(&[("GRASP", [0, 255, 0])]);
        let lit = frame.rgb.chunks(3).filter(|p| *p == [0, 255, 0]).count();
        assert!(lit > 20, "{lit}");
        let [r, _, _] = frame.pixel(40, 40);
        assert_eq!(r, raster::BACKGROUND[0], "below the band is untouched");
    }
}
