//! Mouse camera control: orbit about a pivot in front of the scene camera, pan, zoom.

use glam::{Quat, Vec3};

use crate::scene::{Camera, Scene};

#[derive(Clone, Debug)]
pub struct Orbit {
    base: Camera,
    pivot: Vec3,
    pub yaw: f32,
    pub pitch: f32,
    /// Distance multiplier (zoom).
    pub zoom: f32,
    pub pan: Vec3,
}

impl Orbit {
    /// Pivot: the point on the camera's axis nearest the centre of the scene bounds.
    pub fn new(scene: &Scene) -> Self {
        let c = scene.camera;
        let (lo, hi) = scene.bounds();
        let centre = 0.5 * (lo + hi);
        let d = (centre - c.position)
            .dot(c.forward)
            .max(1e-3 * (hi - lo).length().max(1e-6));
        Self {
            base: c,
            pivot: c.position + c.forward * d,
            yaw: 0.0,
            pitch: 0.0,
            zoom: 1.0,
            pan: Vec3::ZERO,
        }
    }

    pub fn is_identity(&self) -> bool {
        self.yaw == 0.0 && self.pitch == 0.0 && self.zoom == 1.0 && self.pan == Vec3::ZERO
    }

    /// The camera after the user's moves (the scene's camera when untouched).
    pub fn camera(&self) -> Camera {
        if self.is_identity() {
            return self.base;
        }
        let offset = self.base.position - self.pivot;
        let q = Quat::from_axis_angle(Vec3::Y, self.yaw)
            * Quat::from_axis_angle(self.base.right, self.pitch);
        let pivot = self.pivot + self.pan;
        let position = pivot + q * offset * self.zoom;
        let up = q * self.base.up;
        Camera {
            aspect: self.base.aspect,
            ..Camera::look_at(position, pivot, up, self.base.yfov)
        }
    }

    /// Drag by (dx, dy) pixels.
    pub fn rotate(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx * 0.005;
        self.pitch = (self.pitch - dy * 0.005).clamp(-1.5, 1.5);
    }

    /// Pan by (dx, dy) pixels of a view `height` pixels tall.
    pub fn pan_by(&mut self, dx: f32, dy: f32, height: f32) {
        let cam = self.camera();
        let dist = (cam.position - (self.pivot + self.pan)).length();
        let scale = 2.0 * dist * (0.5 * cam.yfov).tan() / height.max(1.0);
        self.pan += (-cam.right * dx + cam.up * dy) * scale;
    }

    pub fn zoom_by(&mut self, scroll: f32) {
        self.zoom = (self.zoom * (-scroll * 0.002).exp()).clamp(0.05, 20.0);
    }
}
