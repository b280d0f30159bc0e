//! Pinhole intrinsics of a MuJoCo camera as sensor_msgs/CameraInfo states them.
//!
//! MuJoCo's cameras are ideal pinholes with square pixels: `fovy` spans the frame height, the
//! principal point is the frame centre, no distortion. Pixel coordinates follow ROS/OpenCV (the
//! centre of the top-left pixel is (0, 0), so the centre of a W-wide frame is (W - 1) / 2), and
//! rows are published top-down in the optical frame (x right, y down, z forward).

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    pub fn from_fovy(fovy_degrees: f64, width: u32, height: u32) -> Self {
        let fy = 0.5 * f64::from(height) / (0.5 * fovy_degrees.to_radians()).tan();
        Self {
            width,
            height,
            fx: fy,
            fy,
            cx: 0.5 * (f64::from(width) - 1.0),
            cy: 0.5 * (f64::from(height) - 1.0),
        }
    }

    /// Row-major 3x3 camera matrix K.
    pub fn k(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }

    /// Row-major 3x4 projection matrix P of a monocular camera (no baseline).
    pub fn p(&self) -> [f64; 12] {
        [
            self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ]
    }

    /// Pixel (u, v) of a point in the optical frame, or `None` behind the camera.
    pub fn project(&self, point: [f64; 3]) -> Option<(f64, f64)> {
        let [x, y, z] = point;
        (z > 0.0).then(|| (self.fx * x / z + self.cx, self.fy * y / z + self.cy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ninety_degrees_puts_the_frame_edge_at_forty_five() {
        let camera = Intrinsics::from_fovy(90.0, 640, 480);
        assert!((camera.fy - 240.0).abs() < 1e-9);
        assert_eq!(camera.fx, camera.fy);
        assert_eq!((camera.cx, camera.cy), (319.5, 239.5));
        // A point 45 degrees below the axis lands half a pixel beyond the last row's centre.
        let (u, v) = camera.project([0.0, 1.0, 1.0]).unwrap();
        assert!(
            (u - 319.5).abs() < 1e-9 && (v - 479.5).abs() < 1e-9,
            "{u} {v}"
        );
        assert!(camera.project([0.0, 0.0, -1.0]).is_none());
    }

    #[test]
    fn matrices_hold_the_focal_lengths_and_centre() {
        let camera = Intrinsics::from_fovy(50.0, 320, 240);
        let k = camera.k();
        assert_eq!(
            (k[0], k[2], k[4], k[5], k[8]),
            (camera.fx, 159.5, camera.fy, 119.5, 1.0)
        );
        let p = camera.p();
        assert_eq!(
            (p[0], p[2], p[5], p[6], p[10], p[3]),
            (camera.fx, 159.5, camera.fy, 119.5, 1.0, 0.0)
        );
    }
}
