//! The coil, its target and the head marker shown on the MRI in 3D Slicer: an OpenIGTLink server
//! (Slicer's OpenIGTLinkIF connects to it as a client) streaming TRANSFORMs in the image's frame
//! (RAS, Slicer's own), from the loop's cycle records, on the logger's thread:
//! - `CoilToImage`: the coil as the robot measures it, through the head marker as tracked now;
//! - `TargetToImage`: the coil's goal on the head (the selected target);
//! - `HeadMarkerToImage`: the head marker, where the registration puts it.
//!
//! At most [`Slicer::rate_hz`] a second: a display needs no more, and the loop's 500 records a
//! second are not all worth a socket write.

use crate::AppError;
use crate::config::Setup;
use mocomp_control::CycleRecord;
use mocomp_frontend::{Observer, Status};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, Timestamp};
use mocomp_kin::Arm;

/// The TRANSFORM device names Slicer shows.
pub const DEVICES: [&str; 3] = ["CoilToImage", "TargetToImage", "HeadMarkerToImage"];

/// The publisher.
pub struct Slicer {
    server: Server,
    arm: Arm,
    base_from_tracker: Isometry3<f64>,
    flange_from_coil: Isometry3<f64>,
    image_from_head: Isometry3<f64>,
    rate_hz: f64,
    last_t: f64,
}

impl std::fmt::Debug for Slicer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Slicer")
            .field("addr", &self.server.local_addr())
            .field("rate_hz", &self.rate_hz)
            .finish_non_exhaustive()
    }
}

impl Slicer {
    /// Serves on `addr` (`host:port`; port 0: any free one) for `setup`'s robot and head, at
    /// most `rate_hz` updates a second.
    pub fn serve(setup: &Setup, addr: &str, rate_hz: f64) -> Result<Self, AppError> {
        let server = Server::bind(addr, ServerConfig::default())
            .map_err(|e| AppError::failed(format!("--slicer {addr}: serving OpenIGTLink"), e))?;
        Ok(Self {
            server,
            arm: setup.arm,
            base_from_tracker: setup.base_from_tracker,
            flange_from_coil: setup.file.flange_from_coil()?,
            image_from_head: setup.file.head.head_from_image.iso().inverse(),
            rate_hz,
            last_t: f64::NEG_INFINITY,
        })
    }

    /// Where it serves.
    pub fn local_addr(&self) -> std::net::SocketAddr {
        self.server.local_addr()
    }

    /// The updates a second it sends at most.
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// The three transforms for a cycle, image frame: the measured coil (when the head is
    /// tracked), the target, the head marker.
    pub fn transforms(&self, r: &CycleRecord) -> [(&'static str, Option<Isometry3<f64>>); 3] {
        let coil = r.head_now.map(|tracker_from_head| {
            let base_from_coil = self.arm.fk_flange(&r.q_actual) * self.flange_from_coil;
            self.image_from_head
                * tracker_from_head.inverse()
                * self.base_from_tracker.inverse()
                * base_from_coil
        });
        [
            (DEVICES[0], coil),
            (
                DEVICES[1],
                Some(self.image_from_head * r.head_from_coil_goal),
            ),
            (DEVICES[2], Some(self.image_from_head)),
        ]
    }
}

impl Observer for Slicer {
    fn event(&mut self, _t: f64, _event: &mocomp_control::Event) {}

    fn status(&mut self, _status: &Status) {}

    fn cycle(&mut self, r: &CycleRecord, _age_s: f64) {
        if r.t - self.last_t < 1.0 / self.rate_hz {
            return;
        }
        self.last_t = r.t;
        let now = Timestamp::now();
        for (device, pose) in self.transforms(r) {
            if let Some(p) = pose
                && let Ok(m) = Message::transform(device, &p, now)
            {
                self.server.send(&m);
            }
        }
    }
}
