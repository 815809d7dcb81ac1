//! The Azure Kinect SDK's C API (`k4a.h`, `k4arecord/playback.h`, `k4arecord/record.h`, SDK
//! 1.4), loaded at run time: the types as `k4atypes.h` lays them out, and a table of the
//! functions mocomp calls, resolved once when the libraries are opened. With [`crate::handles`]
//! (the safe wrappers around each handle), the only code with `unsafe`.
#![allow(unsafe_code, missing_docs)]

use std::ffi::{c_char, c_int, c_void};

/// `k4a_result_t`: `K4A_RESULT_SUCCEEDED` is 0.
pub type K4aResult = c_int;
/// `k4a_buffer_result_t`: 0 succeeded, 1 failed, 2 too small.
pub type BufferResult = c_int;
/// `k4a_wait_result_t`: 0 succeeded, 1 failed, 2 timeout.
pub type WaitResult = c_int;
/// `k4a_stream_result_t`: 0 succeeded, 1 failed, 2 end of file.
pub type StreamResult = c_int;

/// Succeeded (every result enum).
pub const SUCCEEDED: c_int = 0;
/// `K4A_BUFFER_RESULT_TOO_SMALL`.
pub const BUFFER_TOO_SMALL: c_int = 2;
/// `K4A_WAIT_RESULT_TIMEOUT`.
pub const WAIT_TIMEOUT: c_int = 2;
/// `K4A_STREAM_RESULT_EOF`.
pub const STREAM_EOF: c_int = 2;

/// `K4A_IMAGE_FORMAT_DEPTH16`.
pub const FORMAT_DEPTH16: c_int = 4;
/// `K4A_IMAGE_FORMAT_IR16`.
pub const FORMAT_IR16: c_int = 5;
/// `K4A_IMAGE_FORMAT_CUSTOM` (what a recording without colour says its colour format is).
pub const FORMAT_CUSTOM: c_int = 8;

/// An opaque handle (`k4a_device_t`, `k4a_capture_t`, `k4a_image_t`, `k4a_playback_t`,
/// `k4a_record_t`).
pub type Handle = *mut c_void;

/// `k4a_calibration_extrinsics_t`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct Extrinsics {
    /// Row-major 3×3 rotation.
    pub rotation: [f32; 9],
    /// Translation, mm.
    pub translation: [f32; 3],
}

/// `k4a_calibration_intrinsics_t`: the model, its parameter count, and the parameters in the
/// SDK's order: cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1, metric_radius.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct IntrinsicsRaw {
    /// `k4a_calibration_model_type_t`.
    pub model: c_int,
    /// How many of `parameters` are in use.
    pub parameter_count: u32,
    /// The parameters.
    pub parameters: [f32; 15],
}

/// `k4a_calibration_camera_t`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct CameraCalibration {
    /// From this camera to the depth camera.
    pub extrinsics: Extrinsics,
    /// Its lens.
    pub intrinsics: IntrinsicsRaw,
    /// Image width, pixels.
    pub resolution_width: c_int,
    /// Image height, pixels.
    pub resolution_height: c_int,
    /// Where the lens model is valid, normalised radius.
    pub metric_radius: f32,
}

/// `k4a_calibration_t`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct Calibration {
    /// The depth (and IR) camera.
    pub depth_camera: CameraCalibration,
    /// The colour camera.
    pub color_camera: CameraCalibration,
    /// Between the depth camera, the colour camera, the gyro and the accelerometer.
    pub extrinsics: [[Extrinsics; 4]; 4],
    /// `k4a_depth_mode_t`.
    pub depth_mode: c_int,
    /// `k4a_color_resolution_t`.
    pub color_resolution: c_int,
}

/// `k4a_device_configuration_t`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DeviceConfiguration {
    /// `k4a_image_format_t` of colour.
    pub color_format: c_int,
    /// `k4a_color_resolution_t` (0: off).
    pub color_resolution: c_int,
    /// `k4a_depth_mode_t`.
    pub depth_mode: c_int,
    /// `k4a_fps_t`.
    pub camera_fps: c_int,
    /// Only captures with every enabled image.
    pub synchronized_images_only: bool,
    /// Depth's delay after colour, µs.
    pub depth_delay_off_color_usec: i32,
    /// `k4a_wired_sync_mode_t` (0: standalone).
    pub wired_sync_mode: c_int,
    /// A subordinate's delay, µs.
    pub subordinate_delay_off_master_usec: u32,
    /// The streaming LED off.
    pub disable_streaming_indicator: bool,
}

/// `k4a_record_configuration_t`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct RecordConfiguration {
    /// `k4a_image_format_t` of colour.
    pub color_format: c_int,
    /// `k4a_color_resolution_t`.
    pub color_resolution: c_int,
    /// `k4a_depth_mode_t`.
    pub depth_mode: c_int,
    /// `k4a_fps_t`.
    pub camera_fps: c_int,
    /// A colour track.
    pub color_track_enabled: bool,
    /// A depth track.
    pub depth_track_enabled: bool,
    /// An IR track.
    pub ir_track_enabled: bool,
    /// An IMU track.
    pub imu_track_enabled: bool,
    /// Depth's delay after colour, µs.
    pub depth_delay_off_color_usec: i32,
    /// `k4a_wired_sync_mode_t`.
    pub wired_sync_mode: c_int,
    /// A subordinate's delay, µs.
    pub subordinate_delay_off_master_usec: u32,
    /// The first frame's device timestamp, µs.
    pub start_timestamp_offset_usec: u32,
}

/// The functions mocomp calls, with the libraries they come from (never closed, see below).
pub struct Api {
    // Device.
    pub device_get_installed_count: unsafe extern "C" fn() -> u32,
    pub device_open: unsafe extern "C" fn(u32, *mut Handle) -> K4aResult,
    pub device_close: unsafe extern "C" fn(Handle),
    pub device_get_serialnum: unsafe extern "C" fn(Handle, *mut c_char, *mut usize) -> BufferResult,
    pub device_get_calibration:
        unsafe extern "C" fn(Handle, c_int, c_int, *mut Calibration) -> K4aResult,
    pub device_start_cameras: unsafe extern "C" fn(Handle, *const DeviceConfiguration) -> K4aResult,
    pub device_stop_cameras: unsafe extern "C" fn(Handle),
    pub device_get_capture: unsafe extern "C" fn(Handle, *mut Handle, i32) -> WaitResult,
    pub calibration_get_from_raw:
        unsafe extern "C" fn(*mut c_char, usize, c_int, c_int, *mut Calibration) -> K4aResult,
    // Captures and images.
    pub capture_create: unsafe extern "C" fn(*mut Handle) -> K4aResult,
    pub capture_release: unsafe extern "C" fn(Handle),
    pub capture_get_ir_image: unsafe extern "C" fn(Handle) -> Handle,
    pub capture_get_depth_image: unsafe extern "C" fn(Handle) -> Handle,
    pub capture_set_ir_image: unsafe extern "C" fn(Handle, Handle),
    pub capture_set_depth_image: unsafe extern "C" fn(Handle, Handle),
    pub image_create: unsafe extern "C" fn(c_int, c_int, c_int, c_int, *mut Handle) -> K4aResult,
    pub image_release: unsafe extern "C" fn(Handle),
    pub image_get_buffer: unsafe extern "C" fn(Handle) -> *mut u8,
    pub image_get_size: unsafe extern "C" fn(Handle) -> usize,
    pub image_get_format: unsafe extern "C" fn(Handle) -> c_int,
    pub image_get_width_pixels: unsafe extern "C" fn(Handle) -> c_int,
    pub image_get_height_pixels: unsafe extern "C" fn(Handle) -> c_int,
    pub image_get_stride_bytes: unsafe extern "C" fn(Handle) -> c_int,
    pub image_get_device_timestamp_usec: unsafe extern "C" fn(Handle) -> u64,
    pub image_get_system_timestamp_nsec: unsafe extern "C" fn(Handle) -> u64,
    pub image_set_device_timestamp_usec: unsafe extern "C" fn(Handle, u64),
    // Playback.
    pub playback_open: unsafe extern "C" fn(*const c_char, *mut Handle) -> K4aResult,
    pub playback_close: unsafe extern "C" fn(Handle),
    pub playback_get_calibration: unsafe extern "C" fn(Handle, *mut Calibration) -> K4aResult,
    pub playback_get_record_configuration:
        unsafe extern "C" fn(Handle, *mut RecordConfiguration) -> K4aResult,
    pub playback_get_next_capture: unsafe extern "C" fn(Handle, *mut Handle) -> StreamResult,
    pub playback_get_recording_length_usec: unsafe extern "C" fn(Handle) -> u64,
    pub playback_get_tag:
        unsafe extern "C" fn(Handle, *const c_char, *mut c_char, *mut usize) -> BufferResult,
    // Recording.
    pub record_create:
        unsafe extern "C" fn(*const c_char, Handle, DeviceConfiguration, *mut Handle) -> K4aResult,
    pub record_add_tag: unsafe extern "C" fn(Handle, *const c_char, *const c_char) -> K4aResult,
    pub record_add_attachment:
        unsafe extern "C" fn(Handle, *const c_char, *const u8, usize) -> K4aResult,
    pub record_write_header: unsafe extern "C" fn(Handle) -> K4aResult,
    pub record_write_capture: unsafe extern "C" fn(Handle, Handle) -> K4aResult,
    pub record_flush: unsafe extern "C" fn(Handle) -> K4aResult,
    pub record_close: unsafe extern "C" fn(Handle),
    // Never unloaded: the SDK starts threads of its own (libusb's event handling, its logger)
    // that outlive any call, and unloading the code under them crashes the process (seen: a
    // SIGSEGV after a device count of 0). A loaded SDK stays loaded until the process ends.
    _record: std::mem::ManuallyDrop<libloading::Library>,
    _k4a: std::mem::ManuallyDrop<libloading::Library>,
}

impl std::fmt::Debug for Api {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Api").finish_non_exhaustive()
    }
}

/// A library that would not open or lacks a function.
#[derive(Debug)]
pub struct LoadError {
    /// The library or function.
    pub what: String,
    /// The dynamic loader's message.
    pub detail: String,
}

/// Opens `path` (a file, or a name the dynamic loader searches for).
fn open(path: &std::path::Path) -> Result<libloading::Library, LoadError> {
    use libloading::os::unix::{Library, RTLD_GLOBAL, RTLD_NOW};
    // SAFETY: loading runs the library's initialisers; the SDK's do no more than set up its
    // logging. RTLD_GLOBAL lets libk4arecord's reference to libk4a (by its soname) resolve to
    // the copy opened here whatever directory it came from.
    let lib = unsafe { Library::open(Some(path), RTLD_NOW | RTLD_GLOBAL) };
    lib.map(libloading::Library::from).map_err(|e| LoadError {
        what: path.display().to_string(),
        detail: e.to_string(),
    })
}

macro_rules! sym {
    ($lib:expr, $name:literal) => {{
        // SAFETY: the symbol is the SDK 1.4 function of that name, and the field's type is its
        // C signature as k4a.h / record.h / playback.h declare it.
        // The pointer stays valid while the library is open, which the table ensures.
        let s = unsafe { $lib.get(concat!($name, "\0").as_bytes()) };
        match s {
            Ok(f) => *f,
            Err(e) => {
                return Err(LoadError {
                    what: $name.to_string(),
                    detail: e.to_string(),
                });
            }
        }
    }};
}

impl Api {
    /// Opens libk4a then libk4arecord and resolves every function.
    pub fn load(k4a: &std::path::Path, record: &std::path::Path) -> Result<Self, LoadError> {
        let k = open(k4a)?;
        let r = open(record)?;
        Ok(Self {
            device_get_installed_count: sym!(k, "k4a_device_get_installed_count"),
            device_open: sym!(k, "k4a_device_open"),
            device_close: sym!(k, "k4a_device_close"),
            device_get_serialnum: sym!(k, "k4a_device_get_serialnum"),
            device_get_calibration: sym!(k, "k4a_device_get_calibration"),
            device_start_cameras: sym!(k, "k4a_device_start_cameras"),
            device_stop_cameras: sym!(k, "k4a_device_stop_cameras"),
            device_get_capture: sym!(k, "k4a_device_get_capture"),
            calibration_get_from_raw: sym!(k, "k4a_calibration_get_from_raw"),
            capture_create: sym!(k, "k4a_capture_create"),
            capture_release: sym!(k, "k4a_capture_release"),
            capture_get_ir_image: sym!(k, "k4a_capture_get_ir_image"),
            capture_get_depth_image: sym!(k, "k4a_capture_get_depth_image"),
            capture_set_ir_image: sym!(k, "k4a_capture_set_ir_image"),
            capture_set_depth_image: sym!(k, "k4a_capture_set_depth_image"),
            image_create: sym!(k, "k4a_image_create"),
            image_release: sym!(k, "k4a_image_release"),
            image_get_buffer: sym!(k, "k4a_image_get_buffer"),
            image_get_size: sym!(k, "k4a_image_get_size"),
            image_get_format: sym!(k, "k4a_image_get_format"),
            image_get_width_pixels: sym!(k, "k4a_image_get_width_pixels"),
            image_get_height_pixels: sym!(k, "k4a_image_get_height_pixels"),
            image_get_stride_bytes: sym!(k, "k4a_image_get_stride_bytes"),
            image_get_device_timestamp_usec: sym!(k, "k4a_image_get_device_timestamp_usec"),
            image_get_system_timestamp_nsec: sym!(k, "k4a_image_get_system_timestamp_nsec"),
            image_set_device_timestamp_usec: sym!(k, "k4a_image_set_device_timestamp_usec"),
            playback_open: sym!(r, "k4a_playback_open"),
            playback_close: sym!(r, "k4a_playback_close"),
            playback_get_calibration: sym!(r, "k4a_playback_get_calibration"),
            playback_get_record_configuration: sym!(r, "k4a_playback_get_record_configuration"),
            playback_get_next_capture: sym!(r, "k4a_playback_get_next_capture"),
            playback_get_recording_length_usec: sym!(r, "k4a_playback_get_recording_length_usec"),
            playback_get_tag: sym!(r, "k4a_playback_get_tag"),
            record_create: sym!(r, "k4a_record_create"),
            record_add_tag: sym!(r, "k4a_record_add_tag"),
            record_add_attachment: sym!(r, "k4a_record_add_attachment"),
            record_write_header: sym!(r, "k4a_record_write_header"),
            record_write_capture: sym!(r, "k4a_record_write_capture"),
            record_flush: sym!(r, "k4a_record_flush"),
            record_close: sym!(r, "k4a_record_close"),
            _record: std::mem::ManuallyDrop::new(r),
            _k4a: std::mem::ManuallyDrop::new(k),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_structs_have_the_sdks_sizes() {
        // k4atypes.h on x86-64: the sizes the SDK's functions write into.
        assert_eq!(size_of::<Extrinsics>(), 48);
        assert_eq!(size_of::<IntrinsicsRaw>(), 68);
        assert_eq!(size_of::<CameraCalibration>(), 128);
        assert_eq!(size_of::<Calibration>(), 1032);
        assert_eq!(size_of::<DeviceConfiguration>(), 36);
        assert_eq!(size_of::<RecordConfiguration>(), 36);
    }
}
