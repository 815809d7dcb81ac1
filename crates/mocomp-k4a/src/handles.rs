//! The SDK's handles as owned values with safe methods: each is released exactly once, when
//! dropped; each holds the function table (and so the libraries) alive; every buffer the SDK
//! hands out is copied, checked against the image's own size, before its handle is released.
//! With [`crate::ffi`], the only code with `unsafe`; each block says why it is sound.
#![allow(unsafe_code)]

use crate::error::K4aError;
use crate::ffi::{self, Api, Handle};
use std::ffi::{CString, c_char};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The Azure Kinect SDK, loaded (libk4a and libk4arecord 1.4).
#[derive(Debug)]
pub struct Sdk {
    api: Api,
    from: String,
}

/// Where Microsoft's packages install the SDK: found by the dynamic loader's search.
const SYSTEM_K4A: &str = "libk4a.so.1.4";
const SYSTEM_RECORD: &str = "libk4arecord.so.1.4";

/// The library in `dir` whose name is `stem` followed by `.` or `-` (`libk4a.so.1.4`,
/// `libk4a-f64cb9eb.so.1.4.2` as a wheel renames it), the first in name order.
fn find(dir: &Path, stem: &str) -> Result<PathBuf, K4aError> {
    let entries = std::fs::read_dir(dir).map_err(|e| K4aError::SdkMissing {
        tried: dir.display().to_string(),
        detail: e.to_string(),
    })?;
    let mut found: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.strip_prefix(stem))
                .is_some_and(|rest| {
                    (rest.starts_with('.') || rest.starts_with('-')) && rest.contains(".so")
                })
        })
        .collect();
    found.sort();
    found
        .into_iter()
        .next()
        .ok_or_else(|| K4aError::SdkMissing {
            tried: dir.display().to_string(),
            detail: format!("no {stem}*.so* there"),
        })
}

impl Sdk {
    /// Loads the SDK from `dir` (the directory holding libk4a and libk4arecord), or from the
    /// system's library path. Missing: an error that says how to install it.
    pub fn load(dir: Option<&Path>) -> Result<Arc<Self>, K4aError> {
        let (k4a, record, from) = match dir {
            Some(d) => (
                find(d, "libk4a")?,
                find(d, "libk4arecord")?,
                d.display().to_string(),
            ),
            None => (
                PathBuf::from(SYSTEM_K4A),
                PathBuf::from(SYSTEM_RECORD),
                "the system's library path".to_string(),
            ),
        };
        let api = Api::load(&k4a, &record).map_err(|e| K4aError::SdkMissing {
            tried: e.what,
            detail: e.detail,
        })?;
        Ok(Arc::new(Self { api, from }))
    }

    /// Where it was loaded from.
    pub fn loaded_from(&self) -> &str {
        &self.from
    }

    /// Devices connected.
    pub fn installed_devices(&self) -> u32 {
        // SAFETY: takes no arguments; enumerates USB devices.
        unsafe { (self.api.device_get_installed_count)() }
    }
}

impl Sdk {
    /// The depth camera's intrinsics in `mode` from a raw calibration (the JSON a device stores
    /// and a recording attaches as `calibration.json`), as the SDK computes them per mode.
    pub fn intrinsics_from_raw(
        &self,
        raw: &[u8],
        mode: crate::modes::DepthMode,
    ) -> Result<mocomp_vision::Intrinsics, K4aError> {
        // The SDK parses a NUL-terminated copy (it takes a mutable pointer).
        let mut buf = raw.to_vec();
        buf.push(0);
        let mut c = ffi::Calibration::default();
        // SAFETY: `buf` holds `len` bytes including the NUL; `c` is a `k4a_calibration_t` the
        // SDK fills; colour off (0).
        let r = unsafe {
            (self.api.calibration_get_from_raw)(
                buf.as_mut_ptr().cast::<c_char>(),
                buf.len(),
                mode.raw(),
                0,
                &raw mut c,
            )
        };
        if r != ffi::SUCCEEDED {
            return Err(K4aError::Calibration(
                "the SDK cannot read it as a device calibration (calibration.json)".into(),
            ));
        }
        crate::calibration::intrinsics(&c.depth_camera)
    }
}

/// A C string of `s`, refused when it holds a NUL.
fn c_string(s: &str, what: &str) -> Result<CString, K4aError> {
    CString::new(s).map_err(|_| K4aError::BadArgument(format!("{what} {s:?} contains a NUL byte")))
}

fn check(r: ffi::K4aResult, call: &'static str) -> Result<(), K4aError> {
    if r == ffi::SUCCEEDED {
        Ok(())
    } else {
        Err(K4aError::Call { call })
    }
}

/// A 16-bit image copied out of the SDK.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image16 {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major pixels.
    pub data: Vec<u16>,
    /// The device's timestamp (the middle of the exposure), µs.
    pub device_usec: u64,
    /// The host's timestamp when it was read from the device (0 in recordings), ns.
    pub system_nsec: u64,
}

/// A capture's IR and depth images, as far as it has them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Capture16 {
    /// IR (`IR16`).
    pub ir: Option<Image16>,
    /// Depth (`DEPTH16`), mm.
    pub depth: Option<Image16>,
}

/// An image handle (released when dropped).
struct Image<'a> {
    api: &'a Api,
    h: Handle,
}

impl Drop for Image<'_> {
    fn drop(&mut self) {
        // SAFETY: `h` is a live image reference this value owns; released once.
        unsafe { (self.api.image_release)(self.h) }
    }
}

impl Image<'_> {
    /// Copies the pixels out, checking the format and that the buffer holds every row.
    fn read(&self, format: i32, what: &'static str) -> Result<Image16, K4aError> {
        let api = self.api;
        // SAFETY: `h` is a live image; these getters only read its header.
        let (fmt, w, h, stride, size, device_usec, system_nsec) = unsafe {
            (
                (api.image_get_format)(self.h),
                (api.image_get_width_pixels)(self.h),
                (api.image_get_height_pixels)(self.h),
                (api.image_get_stride_bytes)(self.h),
                (api.image_get_size)(self.h),
                (api.image_get_device_timestamp_usec)(self.h),
                (api.image_get_system_timestamp_nsec)(self.h),
            )
        };
        let bad = |detail: String| K4aError::BadImage { what, detail };
        if fmt != format {
            return Err(bad(format!("format {fmt}, expected {format}")));
        }
        let (Ok(wu), Ok(hu), Ok(su)) = (
            usize::try_from(w),
            usize::try_from(h),
            usize::try_from(stride),
        ) else {
            return Err(bad(format!("size {w}×{h}, stride {stride}")));
        };
        let row = wu.checked_mul(2).ok_or_else(|| bad(format!("width {w}")))?;
        let needed = su
            .checked_mul(hu)
            .ok_or_else(|| bad(format!("{h} rows of {stride} bytes")))?;
        if wu == 0 || hu == 0 || su < row || size < needed {
            return Err(bad(format!(
                "{w}×{h}, stride {stride} bytes, buffer {size} bytes"
            )));
        }
        // SAFETY: `h` is live; the buffer is `size` bytes, and `needed` ≤ `size` was checked.
        let ptr = unsafe { (api.image_get_buffer)(self.h) };
        if ptr.is_null() {
            return Err(bad("no buffer".into()));
        }
        // SAFETY: `ptr` points to `size` ≥ `needed` readable bytes owned by the image, which
        // outlives this borrow (it is released only when `self` drops).
        let bytes = unsafe { std::slice::from_raw_parts(ptr, needed) };
        let mut data = Vec::with_capacity(wu * hu);
        for r in 0..hu {
            let line = &bytes[r * su..r * su + row];
            data.extend(
                line.chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]])),
            );
        }
        Ok(Image16 {
            width: w.unsigned_abs(),
            height: h.unsigned_abs(),
            data,
            device_usec,
            system_nsec,
        })
    }
}

/// A capture handle (released when dropped).
struct Capture<'a> {
    api: &'a Api,
    h: Handle,
}

impl Drop for Capture<'_> {
    fn drop(&mut self) {
        // SAFETY: `h` is a live capture reference this value owns; released once.
        unsafe { (self.api.capture_release)(self.h) }
    }
}

impl Capture<'_> {
    fn read(&self) -> Result<Capture16, K4aError> {
        let api = self.api;
        // SAFETY: `h` is a live capture; each getter returns a new reference to its image (or
        // null), which `Image` then owns.
        let (ir, depth) = unsafe {
            (
                (api.capture_get_ir_image)(self.h),
                (api.capture_get_depth_image)(self.h),
            )
        };
        let ir = (!ir.is_null()).then_some(Image { api, h: ir });
        let depth = (!depth.is_null()).then_some(Image { api, h: depth });
        Ok(Capture16 {
            ir: ir
                .map(|i| i.read(ffi::FORMAT_IR16, "IR image"))
                .transpose()?,
            depth: depth
                .map(|i| i.read(ffi::FORMAT_DEPTH16, "depth image"))
                .transpose()?,
        })
    }
}

/// What `k4a_playback_get_next_capture` gave.
pub(crate) enum Next {
    /// A capture.
    Capture(Capture16),
    /// The end of the recording.
    End,
}

/// An open recording (closed when dropped).
pub(crate) struct PlaybackHandle {
    sdk: Arc<Sdk>,
    h: Handle,
}

// SAFETY: the SDK's playback handle may be used from any thread, one at a time; `&mut self`
// methods keep it to one at a time.
unsafe impl Send for PlaybackHandle {}

impl Drop for PlaybackHandle {
    fn drop(&mut self) {
        // SAFETY: `h` is the open playback this value owns; closed once.
        unsafe { (self.sdk.api.playback_close)(self.h) }
    }
}

impl PlaybackHandle {
    pub(crate) fn open(sdk: &Arc<Sdk>, path: &str) -> Result<Self, K4aError> {
        let c = c_string(path, "recording")?;
        let mut h: Handle = std::ptr::null_mut();
        // SAFETY: `c` is a NUL-terminated path; `h` receives the handle.
        let r = unsafe { (sdk.api.playback_open)(c.as_ptr(), &raw mut h) };
        if r != ffi::SUCCEEDED || h.is_null() {
            return Err(K4aError::Recording {
                path: path.to_string(),
                detail: "the SDK cannot open it as an Azure Kinect recording (not Matroska, or \
                         cut short: the index a recording ends with is missing)"
                    .into(),
            });
        }
        Ok(Self {
            sdk: Arc::clone(sdk),
            h,
        })
    }

    pub(crate) fn calibration(&self) -> Result<ffi::Calibration, K4aError> {
        let mut c = ffi::Calibration::default();
        // SAFETY: `h` is open; `c` is a `k4a_calibration_t` the SDK fills.
        let r = unsafe { (self.sdk.api.playback_get_calibration)(self.h, &raw mut c) };
        check(r, "k4a_playback_get_calibration")?;
        Ok(c)
    }

    pub(crate) fn configuration(&self) -> Result<ffi::RecordConfiguration, K4aError> {
        let mut c = ffi::RecordConfiguration::default();
        // SAFETY: `h` is open; `c` is a `k4a_record_configuration_t` the SDK fills.
        let r = unsafe { (self.sdk.api.playback_get_record_configuration)(self.h, &raw mut c) };
        check(r, "k4a_playback_get_record_configuration")?;
        Ok(c)
    }

    pub(crate) fn length_usec(&self) -> u64 {
        // SAFETY: `h` is open.
        unsafe { (self.sdk.api.playback_get_recording_length_usec)(self.h) }
    }

    /// A tag's value (`None`: not there or not text).
    pub(crate) fn tag(&self, name: &str) -> Option<String> {
        let c = c_string(name, "tag").ok()?;
        let mut size = 0usize;
        // SAFETY: asks for the size only (null buffer).
        let r = unsafe {
            (self.sdk.api.playback_get_tag)(self.h, c.as_ptr(), std::ptr::null_mut(), &raw mut size)
        };
        if r != ffi::BUFFER_TOO_SMALL || size == 0 || size > 4096 {
            return None;
        }
        let mut buf = vec![0u8; size];
        // SAFETY: `buf` holds `size` bytes, as the SDK asked for.
        let r = unsafe {
            (self.sdk.api.playback_get_tag)(
                self.h,
                c.as_ptr(),
                buf.as_mut_ptr().cast::<c_char>(),
                &raw mut size,
            )
        };
        if r != ffi::SUCCEEDED {
            return None;
        }
        let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
        String::from_utf8(buf[..end].to_vec()).ok()
    }

    pub(crate) fn next(&mut self) -> Result<Next, K4aError> {
        let mut cap: Handle = std::ptr::null_mut();
        // SAFETY: `h` is open; `cap` receives a capture reference we then own.
        let r = unsafe { (self.sdk.api.playback_get_next_capture)(self.h, &raw mut cap) };
        match r {
            ffi::SUCCEEDED if !cap.is_null() => {
                let c = Capture {
                    api: &self.sdk.api,
                    h: cap,
                };
                c.read().map(Next::Capture)
            }
            ffi::STREAM_EOF => Ok(Next::End),
            _ => Err(K4aError::Call {
                call: "k4a_playback_get_next_capture",
            }),
        }
    }
}

/// A recording being written (closed when dropped).
pub(crate) struct RecordHandle {
    sdk: Arc<Sdk>,
    h: Handle,
}

// SAFETY: as the playback handle: any thread, one at a time (`&mut self`).
unsafe impl Send for RecordHandle {}

impl Drop for RecordHandle {
    fn drop(&mut self) {
        // SAFETY: `h` is the recording this value owns; closed once (which also flushes).
        unsafe { (self.sdk.api.record_close)(self.h) }
    }
}

impl RecordHandle {
    /// A recording of user captures (no device) at `path` with `config`'s tracks.
    pub(crate) fn create(
        sdk: &Arc<Sdk>,
        path: &str,
        config: ffi::DeviceConfiguration,
    ) -> Result<Self, K4aError> {
        let c = c_string(path, "recording")?;
        let mut h: Handle = std::ptr::null_mut();
        // SAFETY: `c` is a NUL-terminated path, no device (null), `config` by value as the C
        // signature takes it; `h` receives the handle.
        let r = unsafe {
            (sdk.api.record_create)(c.as_ptr(), std::ptr::null_mut(), config, &raw mut h)
        };
        if r != ffi::SUCCEEDED || h.is_null() {
            return Err(K4aError::Recording {
                path: path.to_string(),
                detail: "the SDK cannot create it".into(),
            });
        }
        Ok(Self {
            sdk: Arc::clone(sdk),
            h,
        })
    }

    pub(crate) fn add_tag(&mut self, name: &str, value: &str) -> Result<(), K4aError> {
        let (n, v) = (c_string(name, "tag")?, c_string(value, "tag value")?);
        // SAFETY: `h` is open; both strings are NUL-terminated.
        let r = unsafe { (self.sdk.api.record_add_tag)(self.h, n.as_ptr(), v.as_ptr()) };
        check(r, "k4a_record_add_tag")
    }

    pub(crate) fn add_attachment(&mut self, name: &str, data: &[u8]) -> Result<(), K4aError> {
        let n = c_string(name, "attachment")?;
        // SAFETY: `h` is open; `data` is `len` readable bytes, copied by the SDK.
        let r = unsafe {
            (self.sdk.api.record_add_attachment)(self.h, n.as_ptr(), data.as_ptr(), data.len())
        };
        check(r, "k4a_record_add_attachment")
    }

    pub(crate) fn write_header(&mut self) -> Result<(), K4aError> {
        // SAFETY: `h` is open.
        let r = unsafe { (self.sdk.api.record_write_header)(self.h) };
        check(r, "k4a_record_write_header")
    }

    /// Writes a capture of an IR and a depth image, `width`×`height`, at `device_usec`.
    pub(crate) fn write(
        &mut self,
        width: u32,
        height: u32,
        ir: &[u16],
        depth: &[u16],
        device_usec: u64,
    ) -> Result<(), K4aError> {
        let api = &self.sdk.api;
        let n = (width as usize) * (height as usize);
        if ir.len() != n || depth.len() != n {
            return Err(K4aError::BadArgument(format!(
                "a {width}×{height} capture needs {n} pixels per image (IR {}, depth {})",
                ir.len(),
                depth.len()
            )));
        }
        let (Ok(w), Ok(h), Ok(stride)) = (
            i32::try_from(width),
            i32::try_from(height),
            i32::try_from(u64::from(width) * 2),
        ) else {
            return Err(K4aError::BadArgument(format!(
                "{width}×{height} is too large"
            )));
        };
        let mut cap: Handle = std::ptr::null_mut();
        // SAFETY: `cap` receives a new capture we own.
        let r = unsafe { (api.capture_create)(&raw mut cap) };
        check(r, "k4a_capture_create")?;
        let cap = Capture { api, h: cap };
        for (format, pixels) in [(ffi::FORMAT_IR16, ir), (ffi::FORMAT_DEPTH16, depth)] {
            let mut img: Handle = std::ptr::null_mut();
            // SAFETY: `img` receives a new image we own, of `h` rows of `stride` bytes.
            let r = unsafe { (api.image_create)(format, w, h, stride, &raw mut img) };
            check(r, "k4a_image_create")?;
            let img = Image { api, h: img };
            // SAFETY: the image is live.
            let (ptr, size) =
                unsafe { ((api.image_get_buffer)(img.h), (api.image_get_size)(img.h)) };
            if ptr.is_null() || size < n * 2 {
                return Err(K4aError::Call {
                    call: "k4a_image_get_buffer",
                });
            }
            // SAFETY: `ptr` points to `size` ≥ 2n writable bytes the image owns; no other
            // reference to them exists while this slice lives.
            let out = unsafe { std::slice::from_raw_parts_mut(ptr, n * 2) };
            for (o, p) in out.chunks_exact_mut(2).zip(pixels) {
                o.copy_from_slice(&p.to_le_bytes());
            }
            // SAFETY: both handles are live; setting adds the capture's own reference to the
            // image (ours is released when `img` drops).
            unsafe {
                (api.image_set_device_timestamp_usec)(img.h, device_usec);
                if format == ffi::FORMAT_IR16 {
                    (api.capture_set_ir_image)(cap.h, img.h);
                } else {
                    (api.capture_set_depth_image)(cap.h, img.h);
                }
            }
        }
        // SAFETY: `h` is open and its header written; `cap` is live.
        let r = unsafe { (api.record_write_capture)(self.h, cap.h) };
        check(r, "k4a_record_write_capture")
    }

    pub(crate) fn flush(&mut self) -> Result<(), K4aError> {
        // SAFETY: `h` is open.
        let r = unsafe { (self.sdk.api.record_flush)(self.h) };
        check(r, "k4a_record_flush")
    }
}

/// An open device (cameras stopped and closed when dropped).
pub(crate) struct DeviceHandle {
    sdk: Arc<Sdk>,
    h: Handle,
    started: bool,
}

// SAFETY: the SDK's device handle may be used from any thread; `&mut self` keeps it to one.
unsafe impl Send for DeviceHandle {}

impl Drop for DeviceHandle {
    fn drop(&mut self) {
        // SAFETY: `h` is the open device this value owns; stopped (if started) and closed once.
        unsafe {
            if self.started {
                (self.sdk.api.device_stop_cameras)(self.h);
            }
            (self.sdk.api.device_close)(self.h);
        }
    }
}

impl DeviceHandle {
    pub(crate) fn open(sdk: &Arc<Sdk>, index: u32) -> Result<Self, K4aError> {
        let mut h: Handle = std::ptr::null_mut();
        // SAFETY: `h` receives the handle.
        let r = unsafe { (sdk.api.device_open)(index, &raw mut h) };
        check(r, "k4a_device_open")?;
        if h.is_null() {
            return Err(K4aError::Call {
                call: "k4a_device_open",
            });
        }
        Ok(Self {
            sdk: Arc::clone(sdk),
            h,
            started: false,
        })
    }

    pub(crate) fn serial(&self) -> Result<String, K4aError> {
        let mut buf = [0u8; 64];
        let mut size = buf.len();
        // SAFETY: `buf` holds `size` bytes.
        let r = unsafe {
            (self.sdk.api.device_get_serialnum)(
                self.h,
                buf.as_mut_ptr().cast::<c_char>(),
                &raw mut size,
            )
        };
        check(r, "k4a_device_get_serialnum")?;
        let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
        Ok(String::from_utf8_lossy(&buf[..end]).into_owned())
    }

    pub(crate) fn calibration(&self, depth_mode: i32) -> Result<ffi::Calibration, K4aError> {
        let mut c = ffi::Calibration::default();
        // SAFETY: `h` is open; `c` is a `k4a_calibration_t` the SDK fills.
        let r = unsafe { (self.sdk.api.device_get_calibration)(self.h, depth_mode, 0, &raw mut c) };
        check(r, "k4a_device_get_calibration")?;
        Ok(c)
    }

    pub(crate) fn start(&mut self, config: &ffi::DeviceConfiguration) -> Result<(), K4aError> {
        // SAFETY: `h` is open; `config` is read during the call.
        let r = unsafe { (self.sdk.api.device_start_cameras)(self.h, config) };
        check(r, "k4a_device_start_cameras")?;
        self.started = true;
        Ok(())
    }

    /// The next capture within `timeout_ms` (`None`: none came in time); an error when the
    /// device failed (unplugged).
    pub(crate) fn next(&mut self, timeout_ms: i32) -> Result<Option<Capture16>, K4aError> {
        let mut cap: Handle = std::ptr::null_mut();
        // SAFETY: `h` is open and started; `cap` receives a capture reference we then own.
        let r = unsafe { (self.sdk.api.device_get_capture)(self.h, &raw mut cap, timeout_ms) };
        match r {
            ffi::SUCCEEDED if !cap.is_null() => Capture {
                api: &self.sdk.api,
                h: cap,
            }
            .read()
            .map(Some),
            ffi::WAIT_TIMEOUT => Ok(None),
            _ => Err(K4aError::DeviceLost),
        }
    }
}
