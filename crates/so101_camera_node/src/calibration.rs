//! A camera's calibration from the YAML file ROS's camera_calibration writes (and
//! camera_calibration_parsers reads): intrinsics, distortion, rectification and projection for one
//! image size. Pure: parsing and checking; the node reads the file.

use serde::Deserialize;

/// A calibration as the file holds it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Calibration {
    pub image_width: u32,
    pub image_height: u32,
    #[serde(default)]
    pub camera_name: String,
    pub camera_matrix: Matrix,
    pub distortion_model: String,
    pub distortion_coefficients: Matrix,
    pub rectification_matrix: Matrix,
    pub projection_matrix: Matrix,
}

/// `rows`, `cols` and the row-major `data`, as camera_calibration_parsers writes a matrix.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Matrix {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
}

impl Matrix {
    fn of_shape<const N: usize>(
        &self,
        name: &str,
        rows: usize,
        cols: usize,
    ) -> Result<[f64; N], String> {
        if (self.rows, self.cols) != (rows, cols) || self.data.len() != rows * cols {
            return Err(format!(
                "{name} is {}x{} with {} values; a calibration has it {rows}x{cols}",
                self.rows,
                self.cols,
                self.data.len()
            ));
        }
        let mut values = [0.0; N];
        values.copy_from_slice(&self.data);
        Ok(values)
    }
}

/// The matrices of a checked calibration, as CameraInfo carries them.
#[derive(Debug, Clone, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
}

/// Parses a calibration file's text and checks its matrices' shapes.
pub fn parse(text: &str) -> Result<Intrinsics, String> {
    let calibration: Calibration =
        serde_saphyr::from_str(text).map_err(|error| error.to_string())?;
    let d = &calibration.distortion_coefficients;
    if d.rows != 1 || d.data.len() != d.cols {
        return Err(format!(
            "distortion_coefficients is {}x{} with {} values; a calibration has one row",
            d.rows,
            d.cols,
            d.data.len()
        ));
    }
    if calibration.image_width == 0 || calibration.image_height == 0 {
        return Err("image_width and image_height must be above 0".into());
    }
    Ok(Intrinsics {
        width: calibration.image_width,
        height: calibration.image_height,
        distortion_model: calibration.distortion_model,
        d: d.data.clone(),
        k: calibration.camera_matrix.of_shape("camera_matrix", 3, 3)?,
        r: calibration
            .rectification_matrix
            .of_shape("rectification_matrix", 3, 3)?,
        p: calibration
            .projection_matrix
            .of_shape("projection_matrix", 3, 4)?,
    })
}

impl Intrinsics {
    /// A calibration holds for the image size it was made at only.
    pub fn check_size(&self, width: u32, height: u32) -> Result<(), String> {
        if (self.width, self.height) == (width, height) {
            Ok(())
        } else {
            Err(format!(
                "the calibration is of {}x{} images, the camera streams {width}x{height}",
                self.width, self.height
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file as camera_calibration writes it (ost.yaml).
    const OST: &str = "image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [612.5, 0, 320.1, 0, 611.9, 241.3, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.24, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [615.2, 0, 319.5, 0, 0, 614.8, 240.9, 0, 0, 0, 1, 0]
";

    #[test]
    fn a_camera_calibration_file_gives_its_matrices() {
        let intrinsics = parse(OST).unwrap();
        assert_eq!((intrinsics.width, intrinsics.height), (640, 480));
        assert_eq!(intrinsics.distortion_model, "plumb_bob");
        assert_eq!(intrinsics.d, [0.11, -0.24, 0.001, -0.002, 0.0]);
        assert_eq!(intrinsics.k[0], 612.5);
        assert_eq!(intrinsics.k[5], 241.3);
        assert_eq!(intrinsics.p[2], 319.5);
        assert_eq!(intrinsics.r[4], 1.0);
        assert!(intrinsics.check_size(640, 480).is_ok());
        let refused = intrinsics.check_size(1280, 720).unwrap_err();
        assert!(refused.contains("640x480"), "{refused}");
    }

    #[test]
    fn a_malformed_calibration_says_what_is_wrong() {
        let short = OST.replace(
            "data: [612.5, 0, 320.1, 0, 611.9, 241.3, 0, 0, 1]",
            "data: [612.5, 0]",
        );
        let refused = parse(&short).unwrap_err();
        assert!(refused.contains("camera_matrix"), "{refused}");
        let missing = OST.replace("distortion_model: plumb_bob\n", "");
        assert!(parse(&missing).unwrap_err().contains("distortion_model"));
        assert!(parse("not: [a, calibration").is_err());
    }
}
