//! Real backgrounds in sim frames: pictures of a user's empty workspace (one folder per camera, as
//! `so101_camera_node --snapshot` saves them), one drawn per episode and camera, shown wherever the
//! scene's scenery (floor, table, sky) would be, behind the arm, the cube and the bin.
//!
//! In one render pass: the physics thread paints the scenery's geoms of a view in a key colour no
//! lit surface of the scene can take (pure green, saturated by emission, no texture or highlight)
//! and encloses the view in a key-coloured sphere for the sky; the render thread swaps each pixel of
//! exactly that colour for the picture's. The scene renders without multisampling
//! (`offsamples="0"`), so every pixel is scenery or not, never a blend. Pure: pictures in, pixels
//! out; the rig does the I/O.

use std::{
    fs,
    path::{Path, PathBuf},
};

use zune_jpeg::{
    zune_core::{bytestream::ZCursor, colorspace::ColorSpace, options::DecoderOptions},
    JpegDecoder,
};

/// The colour the scenery is painted in: no surface of the scene reaches it under any light of
/// the randomization (every lit colour keeps some red or blue, and highlights add both).
pub const KEY: [u8; 3] = [0, 255, 0];

/// Picture files taken from a camera's folder.
const EXTENSIONS: [&str; 2] = ["jpg", "jpeg"];

#[derive(Debug, thiserror::Error)]
pub enum BackgroundError {
    #[error("backgrounds {dir}: cannot read {path}: {reason}")]
    Read {
        dir: PathBuf,
        path: PathBuf,
        reason: String,
    },
    #[error(
        "backgrounds {dir}: no picture for camera {camera} ({dir}/{camera}/*.jpg: save them with so101_camera_node --snapshot)"
    )]
    Missing { dir: PathBuf, camera: String },
}

/// One picture, rows top-down, RGB.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
}

/// The pictures of each camera that shows a background, in file-name order.
#[derive(Debug, Clone)]
pub struct Backgrounds {
    pub dir: PathBuf,
    /// Per camera (by the rig's camera index): its pictures, empty for a camera that keeps the
    /// sim's own scenery (one riding the arm).
    pictures: Vec<Vec<Picture>>,
}

impl Backgrounds {
    /// Reads `dir/NAME/*.jpg` for every camera of `cameras` that `wanted` (fixed cameras); each of
    /// those must have at least one picture.
    pub fn load(dir: &Path, cameras: &[(String, bool)]) -> Result<Self, BackgroundError> {
        let mut pictures = Vec::with_capacity(cameras.len());
        for (name, wanted) in cameras {
            if !wanted {
                pictures.push(Vec::new());
                continue;
            }
            let folder = dir.join(name);
            let mut files: Vec<PathBuf> = fs::read_dir(&folder)
                .map(|entries| {
                    entries
                        .filter_map(|entry| entry.ok().map(|entry| entry.path()))
                        .filter(|path| is_picture(path))
                        .collect()
                })
                .unwrap_or_default();
            files.sort();
            if files.is_empty() {
                return Err(BackgroundError::Missing {
                    dir: dir.to_owned(),
                    camera: name.clone(),
                });
            }
            let read = |path: &PathBuf| {
                let bytes = fs::read(path).map_err(|error| error.to_string())?;
                decode_jpeg(&bytes)
            };
            let decoded = files
                .iter()
                .map(|path| {
                    read(path).map_err(|reason| BackgroundError::Read {
                        dir: dir.to_owned(),
                        path: path.clone(),
                        reason,
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            pictures.push(decoded);
        }
        Ok(Self {
            dir: dir.to_owned(),
            pictures,
        })
    }

    /// Whether camera `camera` shows a background.
    pub fn shows(&self, camera: usize) -> bool {
        self.pictures
            .get(camera)
            .is_some_and(|list| !list.is_empty())
    }

    /// The index of the picture camera `camera` shows in the episode of `draw`: each camera draws
    /// its own, so two cameras need not show pictures of the same moment.
    pub fn pick(&self, camera: usize, draw: u64) -> Option<usize> {
        let count = self.pictures.get(camera)?.len();
        (count > 0).then(|| {
            (mix(draw ^ (camera as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)) % count as u64)
                as usize
        })
    }

    pub fn picture(&self, camera: usize, index: usize) -> &Picture {
        &self.pictures[camera][index]
    }
}

fn is_picture(path: &Path) -> bool {
    path.extension()
        .and_then(|extension| extension.to_str())
        .is_some_and(|extension| EXTENSIONS.contains(&extension.to_ascii_lowercase().as_str()))
}

/// SplitMix64's finaliser: spreads a draw over all bits before the modulo.
fn mix(mut value: u64) -> u64 {
    value = (value ^ (value >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    value = (value ^ (value >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    value ^ (value >> 31)
}

pub fn decode_jpeg(bytes: &[u8]) -> Result<Picture, String> {
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    decoder
        .decode_headers()
        .map_err(|error| format!("not a JPEG: {error}"))?;
    let (width, height) = decoder
        .dimensions()
        .ok_or_else(|| "a JPEG without a size".to_owned())?;
    let rgb = decoder.decode().map_err(|error| error.to_string())?;
    if rgb.len() != 3 * width * height {
        return Err(format!(
            "a {width}x{height} JPEG decoded to {} bytes",
            rgb.len()
        ));
    }
    Ok(Picture { width, height, rgb })
}

/// `picture` fitted to a `width` x `height` frame, rows bottom-up as GL reads frames: cropped
/// about its centre to the frame's aspect, then each frame pixel the mean of the picture pixels
/// whose centres fall within it (the nearest one where the picture is smaller).
pub fn fitted_bottom_up(picture: &Picture, width: usize, height: usize) -> Vec<u8> {
    // The centred crop of the frame's aspect.
    let (crop_width, crop_height) = if picture.width * height > picture.height * width {
        ((picture.height * width / height).max(1), picture.height)
    } else {
        (picture.width, (picture.width * height / width).max(1))
    };
    let (left, top) = (
        (picture.width - crop_width) / 2,
        (picture.height - crop_height) / 2,
    );
    let scale_x = crop_width as f64 / width as f64;
    let scale_y = crop_height as f64 / height as f64;
    let span = |index: usize, scale: f64, limit: usize| {
        let start = ((index as f64 * scale).round() as usize).min(limit - 1);
        let end = (((index + 1) as f64 * scale).round() as usize).clamp(start + 1, limit);
        start..end
    };
    let mut out = Vec::with_capacity(3 * width * height);
    for row in (0..height).rev() {
        let rows = span(row, scale_y, crop_height);
        for column in 0..width {
            let columns = span(column, scale_x, crop_width);
            let mut sum = [0u32; 3];
            let mut count = 0u32;
            for y in rows.clone() {
                let line = (top + y) * picture.width;
                for x in columns.clone() {
                    let at = 3 * (line + left + x);
                    for (total, &value) in sum.iter_mut().zip(&picture.rgb[at..at + 3]) {
                        *total += u32::from(value);
                    }
                    count += 1;
                }
            }
            out.extend(sum.map(|total| ((total + count / 2) / count) as u8));
        }
    }
    out
}

/// Puts `background` wherever `frame` shows the key colour (both the same size and row order).
pub fn composite(frame: &mut [u8], background: &[u8]) {
    for (pixel, behind) in frame.chunks_exact_mut(3).zip(background.chunks_exact(3)) {
        if pixel == KEY {
            pixel.copy_from_slice(behind);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn picture(width: usize, height: usize, pixel: impl Fn(usize, usize) -> [u8; 3]) -> Picture {
        let mut rgb = Vec::new();
        for y in 0..height {
            for x in 0..width {
                rgb.extend(pixel(x, y));
            }
        }
        Picture { width, height, rgb }
    }

    #[test]
    fn only_key_pixels_are_replaced() {
        let mut frame = vec![0, 255, 0, 10, 20, 30, 0, 254, 0, 0, 255, 0];
        let background = vec![1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13];
        composite(&mut frame, &background);
        assert_eq!(frame, vec![1, 2, 3, 10, 20, 30, 0, 254, 0, 11, 12, 13]);
    }

    #[test]
    fn a_picture_is_averaged_down_and_flipped_bottom_up() {
        // 4x2, left half dark, right half bright, top row +1: to 2x1, then 2x2.
        let big = picture(4, 2, |x, y| {
            let base = if x < 2 { 10 } else { 200 };
            [base + y as u8; 3]
        });
        assert_eq!(
            fitted_bottom_up(&big, 2, 1),
            vec![11, 11, 11, 201, 201, 201]
        );
        let same = fitted_bottom_up(&big, 4, 2);
        // Bottom-up: the picture's second row comes first.
        assert_eq!(same[..3], [11, 11, 11]);
        assert_eq!(same[12..15], [10, 10, 10]);
    }

    #[test]
    fn a_wider_picture_is_cropped_about_its_centre() {
        // 8x2 where only the middle 4 columns are bright: fitted to a 2x1 (same aspect as 4x2),
        // the crop keeps the middle and drops the dark sides.
        let wide = picture(8, 2, |x, _| {
            if (2..6).contains(&x) {
                [200; 3]
            } else {
                [0; 3]
            }
        });
        assert_eq!(fitted_bottom_up(&wide, 2, 1), vec![200; 6]);
        // Smaller than the frame: nearest pixels, no gaps.
        let tiny = picture(1, 1, |_, _| [7, 8, 9]);
        assert_eq!(fitted_bottom_up(&tiny, 3, 2), [7, 8, 9].repeat(6));
    }

    #[test]
    fn each_camera_draws_its_own_picture_per_episode() {
        let backgrounds = Backgrounds {
            dir: PathBuf::from("x"),
            pictures: vec![
                vec![picture(1, 1, |_, _| [0; 3]); 5],
                Vec::new(),
                vec![picture(1, 1, |_, _| [0; 3]); 5],
            ],
        };
        assert!(backgrounds.shows(0) && !backgrounds.shows(1) && backgrounds.shows(2));
        assert_eq!(backgrounds.pick(1, 3), None);
        let picks: Vec<usize> = (0..200)
            .filter_map(|draw| backgrounds.pick(0, draw))
            .collect();
        for index in 0..5 {
            assert!(picks.contains(&index), "picture {index} never drawn");
        }
        let differ = (0..50).filter(|&draw| backgrounds.pick(0, draw) != backgrounds.pick(2, draw));
        assert!(differ.count() > 20);
        assert_eq!(backgrounds.pick(0, 42), backgrounds.pick(0, 42));
    }

    #[test]
    fn missing_folders_and_broken_files_are_named() {
        let dir = std::env::temp_dir().join(format!("so101_backgrounds_{}", std::process::id()));
        fs::create_dir_all(dir.join("top")).unwrap();
        fs::write(dir.join("top/a.jpg"), b"not a jpeg").unwrap();
        let cameras = [("top".to_owned(), true), ("wrist".to_owned(), false)];
        let error = Backgrounds::load(&dir, &cameras).unwrap_err().to_string();
        assert!(
            error.contains("a.jpg") && error.contains("not a JPEG"),
            "{error}"
        );
        let cameras = [("front".to_owned(), true)];
        let error = Backgrounds::load(&dir, &cameras).unwrap_err().to_string();
        assert!(
            error.contains("camera front") && error.contains("--snapshot"),
            "{error}"
        );
        fs::remove_dir_all(&dir).unwrap();
    }
}
