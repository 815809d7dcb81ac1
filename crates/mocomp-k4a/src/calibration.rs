//! The SDK's factory calibration of the depth camera (per depth mode, as the device or the
//! recording reports it) as the pipeline's [`Intrinsics`]: Brown–Conrady with six radial terms
//! (OpenCV's rational model), principal point with pixel centres at integers (the SDK's
//! convention: its cx, cy already carry the −0.5 of the crop from the sensor's normalised
//! calibration). Pure.

use crate::error::K4aError;
use crate::ffi::CameraCalibration;
use mocomp_vision::Intrinsics;
use mocomp_vision::intrinsics::PixelCentre;

/// `K4A_CALIBRATION_LENS_DISTORTION_MODEL_POLYNOMIAL_3K`.
const POLYNOMIAL_3K: i32 = 2;
/// `K4A_CALIBRATION_LENS_DISTORTION_MODEL_RATIONAL_6KT`: the SDK's older model, whose tangential
/// terms lack Brown–Conrady's factor of 2; devices report Brown–Conrady.
const RATIONAL_6KT: i32 = 3;
/// `K4A_CALIBRATION_LENS_DISTORTION_MODEL_BROWN_CONRADY`.
const BROWN_CONRADY: i32 = 4;

/// The camera's lens as [`Intrinsics`].
pub(crate) fn intrinsics(c: &CameraCalibration) -> Result<Intrinsics, K4aError> {
    let i = &c.intrinsics;
    match i.model {
        BROWN_CONRADY | POLYNOMIAL_3K => {}
        RATIONAL_6KT => {
            return Err(K4aError::Calibration(
                "the lens model is RATIONAL_6KT, whose tangential terms differ from \
                 Brown-Conrady's; only BROWN_CONRADY (and POLYNOMIAL_3K) are taken"
                    .into(),
            ));
        }
        m => {
            return Err(K4aError::Calibration(format!(
                "lens model {m} is not one mocomp takes (BROWN_CONRADY)"
            )));
        }
    }
    let p = i.parameters.map(f64::from);
    let [
        cx,
        cy,
        fx,
        fy,
        k1,
        k2,
        k3,
        k4,
        k5,
        k6,
        codx,
        cody,
        p2,
        p1,
        _radius,
    ] = p;
    if codx != 0.0 || cody != 0.0 {
        return Err(K4aError::Calibration(format!(
            "the centre of distortion is off the principal point ({codx}, {cody})"
        )));
    }
    let (Ok(width), Ok(height)) = (
        u32::try_from(c.resolution_width),
        u32::try_from(c.resolution_height),
    ) else {
        return Err(K4aError::Calibration(format!(
            "resolution {}×{}",
            c.resolution_width, c.resolution_height
        )));
    };
    let k = Intrinsics {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        k1,
        k2,
        k3,
        k4,
        k5,
        k6,
        p1,
        p2,
        pixel_centre: PixelCentre::Integer,
    };
    k.validate("the depth camera's calibration")
        .map_err(|e| K4aError::Calibration(e.to_string()))?;
    Ok(k)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::ffi::IntrinsicsRaw;

    fn camera(model: i32) -> CameraCalibration {
        CameraCalibration {
            intrinsics: IntrinsicsRaw {
                model,
                parameter_count: 14,
                parameters: [
                    332.5, 348.5, 504.5, 504.75, 0.5, -0.02, -0.0025, 0.875, 0.0625, -0.015625,
                    0.0, 0.0, -7.0e-5, 2.0e-5, 1.7,
                ],
            },
            resolution_width: 640,
            resolution_height: 576,
            metric_radius: 1.7,
            ..CameraCalibration::default()
        }
    }

    #[test]
    fn the_sdks_parameter_order_lands_in_the_right_fields() {
        let k = intrinsics(&camera(BROWN_CONRADY)).unwrap();
        assert_eq!((k.width, k.height), (640, 576));
        assert_eq!((k.cx, k.cy, k.fx, k.fy), (332.5, 348.5, 504.5, 504.75));
        assert_eq!((k.k1, k.k4, k.k6), (0.5, 0.875, -0.015625));
        // The SDK stores p2 before p1.
        assert_eq!(
            (f64::from(2.0e-5_f32), f64::from(-7.0e-5_f32)),
            (k.p1, k.p2)
        );
        assert_eq!(k.pixel_centre, PixelCentre::Integer);
    }

    #[test]
    fn other_lens_models_and_a_shifted_centre_are_refused_by_name() {
        let e = intrinsics(&camera(RATIONAL_6KT)).unwrap_err().to_string();
        assert!(e.contains("RATIONAL_6KT"), "{e}");
        assert!(intrinsics(&camera(1)).is_err());
        let mut c = camera(BROWN_CONRADY);
        c.intrinsics.parameters[10] = 0.1;
        let e = intrinsics(&c).unwrap_err().to_string();
        assert!(e.contains("centre of distortion"), "{e}");
        let mut c = camera(BROWN_CONRADY);
        c.resolution_width = -1;
        assert!(intrinsics(&c).is_err());
        let mut c = camera(BROWN_CONRADY);
        c.intrinsics.parameters[2] = f32::NAN;
        assert!(intrinsics(&c).is_err());
    }
}
