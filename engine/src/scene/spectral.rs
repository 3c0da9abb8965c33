//! A [`Scene`] projected onto one bin grid: per-bin reflectances, indices and emission,
//! the BVH, the light list with its sampling distribution, and what the scene needs
//! (specular paths? dispersion?). Immutable and shared by every thread of a render.

use glam::Vec3;

use super::{MaterialKind, PunctualKind, Scene};
use crate::geometry::{Accel, triangle_normal};
use crate::sampling::{cdf, one_minus_cos};
use crate::spectral::{BinGrid, Role, Transport};

/// Surface behaviour with per-bin data.
#[derive(Clone, Debug)]
pub enum SurfaceKind {
    Diffuse {
        reflectance: Vec<f32>,
    },
    Mirror {
        reflectance: Vec<f32>,
    },
    /// `eta[i]`: index in bin i; `dispersive`: whether the bins differ.
    Dielectric {
        eta: Vec<f32>,
        dispersive: bool,
    },
}

#[derive(Clone, Debug)]
pub struct SMaterial {
    pub name: String,
    pub kind: SurfaceKind,
    pub emission: Option<Vec<f32>>,
}

/// A triangle with what shading needs precomputed.
#[derive(Clone, Copy, Debug)]
pub struct TriData {
    pub v0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Unit geometric normal (front face: counter-clockwise winding).
    pub normal: Vec3,
    pub area: f32,
    pub material: u32,
}

#[derive(Clone, Debug)]
pub enum LightKind {
    /// An emissive triangle (one-sided, Lambertian).
    Area {
        tri: u32,
    },
    Point {
        position: Vec3,
    },
    Spot {
        position: Vec3,
        axis: Vec3,
        /// 1 − cos of the outer and inner cone angles (precise for narrow cones).
        omc_outer: f32,
        omc_inner: f32,
    },
}

#[derive(Clone, Debug)]
pub struct Light {
    pub kind: LightKind,
    /// Per-bin emitted radiance (area) or intensity (punctual).
    pub spectrum: Vec<f32>,
    /// Emitted power as luminance (Y), for choosing lights.
    pub power: f32,
}

pub struct SpectralScene {
    pub name: String,
    pub grid: BinGrid,
    pub accel: Accel,
    pub tris: Vec<TriData>,
    pub materials: Vec<SMaterial>,
    pub lights: Vec<Light>,
    /// Photon emission: light i chosen with probability `emit_pmf[i]`.
    pub emit_pmf: Vec<f32>,
    pub emit_cdf: Vec<f32>,
    /// Direct lighting: light i sampled with probability proportional to its power.
    pub direct_pmf: Vec<f32>,
    pub direct_cdf: Vec<f32>,
    pub camera: super::Camera,
    pub bounds: (Vec3, Vec3),
    /// Total area of diffuse triangles (for the default gather radius).
    pub diffuse_area: f64,
    /// Whether any surface is specular (mirror or glass): else no caustic map is built.
    pub has_specular: bool,
    /// Whether any glass disperses on this grid: else no photon is ever split.
    pub has_dispersion: bool,
    pub warnings: Vec<String>,
}

impl SpectralScene {
    pub fn new(scene: &Scene, grid: BinGrid) -> Self {
        let n = grid.len();
        let mut warnings = scene.warnings.clone();
        let materials: Vec<SMaterial> = scene
            .materials
            .iter()
            .map(|m| {
                // Reflectances above 1 (Smits' basis reaches 1.0007) would add energy.
                let refl = |s| -> Vec<f32> {
                    grid.project(s, Role::Reflectance)
                        .into_iter()
                        .map(|v| v.min(1.0))
                        .collect()
                };
                let kind = match &m.kind {
                    MaterialKind::Diffuse { reflectance } => SurfaceKind::Diffuse {
                        reflectance: refl(reflectance),
                    },
                    MaterialKind::Mirror { reflectance } => SurfaceKind::Mirror {
                        reflectance: refl(reflectance),
                    },
                    MaterialKind::Dielectric { ior } => {
                        let eta: Vec<f32> = (0..n)
                            .map(|i| ior.eta(grid.ior_wavelength(i)) as f32)
                            .collect();
                        let dispersive = grid.transport() == Transport::Spectral
                            && n > 1
                            && ior.is_dispersive()
                            && eta.iter().any(|&e| e != eta[0]);
                        SurfaceKind::Dielectric { eta, dispersive }
                    }
                };
                SMaterial {
                    name: m.name.clone(),
                    kind,
                    emission: m.emission.as_ref().map(|e| grid.project(e, Role::Emission)),
                }
            })
            .collect();

        let mut tris = Vec::with_capacity(scene.triangles.len());
        let mut lights = Vec::new();
        let mut diffuse_area = 0.0f64;
        for (i, (t, &m)) in scene
            .triangles
            .iter()
            .zip(&scene.triangle_material)
            .enumerate()
        {
            let (twice_area, normal) = triangle_normal(t);
            let area = 0.5 * twice_area;
            tris.push(TriData {
                v0: t[0],
                e1: t[1] - t[0],
                e2: t[2] - t[0],
                normal,
                area,
                material: m,
            });
            let mat = &materials[m as usize];
            if matches!(mat.kind, SurfaceKind::Diffuse { .. }) {
                diffuse_area += area as f64;
            }
            if let Some(e) = &mat.emission {
                let y = luminance_of(&grid, e);
                if area > 0.0 && y > 0.0 {
                    lights.push(Light {
                        kind: LightKind::Area { tri: i as u32 },
                        spectrum: e.clone(),
                        power: (y * std::f64::consts::PI * area as f64) as f32,
                    });
                }
            }
        }
        for l in &scene.lights {
            let spectrum = grid.project(&l.intensity, Role::Emission);
            let y = luminance_of(&grid, &spectrum);
            let (kind, solid_angle) = match l.kind {
                PunctualKind::Point => (
                    LightKind::Point {
                        position: l.position,
                    },
                    4.0 * std::f64::consts::PI,
                ),
                PunctualKind::Spot {
                    direction,
                    inner,
                    outer,
                } => (
                    LightKind::Spot {
                        position: l.position,
                        axis: direction,
                        omc_outer: one_minus_cos(outer),
                        omc_inner: one_minus_cos(inner.min(outer)),
                    },
                    2.0 * std::f64::consts::PI * one_minus_cos(outer) as f64,
                ),
            };
            if y > 0.0 {
                lights.push(Light {
                    kind,
                    spectrum,
                    power: (y * solid_angle) as f32,
                });
            } else {
                warnings.push(format!("light '{}' is black and is skipped", l.name));
            }
        }
        // Photons: half of them by power, half evenly over light *groups* (all area
        // triangles of one material count as one group), so a small bright spot next to a
        // large dim panel still gets enough photons for its caustic.
        let total: f64 = lights.iter().map(|l| l.power as f64).sum();
        let group_of = |l: &Light| -> usize {
            match l.kind {
                LightKind::Area { tri } => tris[tri as usize].material as usize,
                _ => usize::MAX,
            }
        };
        let mut groups: Vec<(usize, f64)> = Vec::new(); // (group id, power) — punctual lights are their own group
        let mut light_group = Vec::with_capacity(lights.len());
        for (i, l) in lights.iter().enumerate() {
            let g = group_of(l);
            let key = if g == usize::MAX { usize::MAX - i } else { g };
            let idx = match groups.iter().position(|(k, _)| *k == key) {
                Some(p) => p,
                None => {
                    groups.push((key, 0.0));
                    groups.len() - 1
                }
            };
            groups[idx].1 += l.power as f64;
            light_group.push(idx);
        }
        let emit_pmf: Vec<f32> = lights
            .iter()
            .zip(&light_group)
            .map(|(l, &g)| {
                let by_power = l.power as f64 / total;
                let group_share = 1.0 / groups.len() as f64;
                let in_group = l.power as f64 / groups[g].1;
                (0.5 * by_power + 0.5 * group_share * in_group) as f32
            })
            .collect();
        let direct_pmf: Vec<f32> = lights
            .iter()
            .map(|l| (l.power as f64 / total) as f32)
            .collect();
        let has_specular = materials
            .iter()
            .any(|m| !matches!(m.kind, SurfaceKind::Diffuse { .. }));
        let has_dispersion = materials.iter().any(|m| {
            matches!(
                m.kind,
                SurfaceKind::Dielectric {
                    dispersive: true,
                    ..
                }
            )
        });
        Self {
            name: scene.name.clone(),
            accel: Accel::new(&scene.triangles),
            emit_cdf: cdf(&emit_pmf),
            direct_cdf: cdf(&direct_pmf),
            emit_pmf,
            direct_pmf,
            grid,
            tris,
            materials,
            lights,
            camera: scene.camera,
            bounds: scene.bounds(),
            diffuse_area,
            has_specular,
            has_dispersion,
            warnings,
        }
    }

    pub fn bins(&self) -> usize {
        self.grid.len()
    }

    pub fn material_of(&self, prim: u32) -> &SMaterial {
        &self.materials[self.tris[prim as usize].material as usize]
    }

    pub fn diagonal(&self) -> f32 {
        (self.bounds.1 - self.bounds.0).length()
    }
}

fn luminance_of(grid: &BinGrid, v: &[f32]) -> f64 {
    grid.to_xyz(v)[1]
}
