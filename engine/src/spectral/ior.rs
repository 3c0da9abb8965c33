//! Index-of-refraction models: constant, Sellmeier (named glasses) and glTF's Abbe-number
//! form (`KHR_materials_dispersion`).

use super::tables::{GlassEntry, find_glass, glass_names};

#[derive(Clone, Debug, PartialEq)]
pub enum IorModel {
    /// The same index at every wavelength (no dispersion).
    Constant(f64),
    /// n²(λ) = 1 + Σ Bᵢ λ² / (λ² − Cᵢ), λ in µm, Cᵢ in µm².
    Sellmeier {
        name: String,
        b: [f64; 3],
        c: [f64; 3],
    },
    /// glTF `KHR_materials_dispersion`:
    /// n(λ) = max(n_d + (n_d − 1)/V_d · (523655/λ² − 1.5168), 1), λ in nm.
    Abbe { nd: f64, vd: f64 },
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IorError {
    #[error("unknown glass '{name}' (known: {known})")]
    UnknownGlass { name: String, known: String },
    #[error("index of refraction {0} must be finite and ≥ 1")]
    BadIndex(f64),
    #[error("Abbe number {0} must be finite and > 0")]
    BadAbbe(f64),
    #[error(
        "Sellmeier glass '{name}': index is not finite or below 1 at {lambda_nm} nm (pole or bad coefficients)"
    )]
    BadSellmeier { name: String, lambda_nm: f64 },
}

impl IorModel {
    pub fn glass(name: &str) -> Result<Self, IorError> {
        let g = find_glass(name).ok_or_else(|| IorError::UnknownGlass {
            name: name.to_string(),
            known: glass_names().join(", "),
        })?;
        Ok(Self::from_entry(g))
    }

    pub fn from_entry(g: &GlassEntry) -> Self {
        Self::Sellmeier {
            name: g.name.clone(),
            b: g.b,
            c: g.c,
        }
    }

    pub fn constant(n: f64) -> Result<Self, IorError> {
        if n.is_finite() && n >= 1.0 {
            Ok(Self::Constant(n))
        } else {
            Err(IorError::BadIndex(n))
        }
    }

    pub fn abbe(nd: f64, vd: f64) -> Result<Self, IorError> {
        if !(nd.is_finite() && nd >= 1.0) {
            return Err(IorError::BadIndex(nd));
        }
        if !(vd.is_finite() && vd > 0.0) {
            return Err(IorError::BadAbbe(vd));
        }
        Ok(Self::Abbe { nd, vd })
    }

    /// Index at `lambda_nm`.
    pub fn eta(&self, lambda_nm: f64) -> f64 {
        match self {
            Self::Constant(n) => *n,
            Self::Sellmeier { b, c, .. } => {
                let l2 = (lambda_nm * 1e-3).powi(2);
                let n2 = 1.0 + (0..3).map(|i| b[i] * l2 / (l2 - c[i])).sum::<f64>();
                n2.max(0.0).sqrt()
            }
            Self::Abbe { nd, vd } => {
                (nd + (nd - 1.0) / vd * (523_655.0 / (lambda_nm * lambda_nm) - 1.5168)).max(1.0)
            }
        }
    }

    /// Whether the index depends on wavelength.
    pub fn is_dispersive(&self) -> bool {
        !matches!(self, Self::Constant(_))
    }

    /// Checks the index over `[lambda_min, lambda_max]`: finite and ≥ 1 everywhere (a
    /// Sellmeier pole inside the range makes it diverge or n² ≤ 0, both rejected).
    pub fn validate(&self, lambda_min: f64, lambda_max: f64) -> Result<(), IorError> {
        if let Self::Sellmeier { name, c, .. } = self {
            for ci in c {
                let pole_nm = ci.max(0.0).sqrt() * 1e3;
                if pole_nm >= lambda_min && pole_nm <= lambda_max {
                    return Err(IorError::BadSellmeier {
                        name: name.clone(),
                        lambda_nm: pole_nm,
                    });
                }
            }
            let steps = ((lambda_max - lambda_min).max(0.0)).ceil() as usize + 1;
            for s in 0..=steps {
                let l = lambda_min + (lambda_max - lambda_min) * s as f64 / steps as f64;
                let l2 = (l * 1e-3).powi(2);
                let n2 = 1.0 + (0..3).map(|i| self.b()[i] * l2 / (l2 - c[i])).sum::<f64>();
                if !n2.is_finite() || n2 < 1.0 {
                    return Err(IorError::BadSellmeier {
                        name: name.clone(),
                        lambda_nm: l,
                    });
                }
            }
        }
        Ok(())
    }

    fn b(&self) -> [f64; 3] {
        match self {
            Self::Sellmeier { b, .. } => *b,
            _ => [0.0; 3],
        }
    }

    /// A short human description ("N-SF11 (Sellmeier)", "1.5", "n_d 1.5, V_d 40").
    pub fn describe(&self) -> String {
        match self {
            Self::Constant(n) => format!("n = {n}"),
            Self::Sellmeier { name, .. } => format!("{name} (Sellmeier)"),
            Self::Abbe { nd, vd } => format!("n_d = {nd}, V_d = {vd:.2} (Abbe)"),
        }
    }
}

/// Fraunhofer lines used for n_d and the Abbe number.
pub const LAMBDA_D: f64 = 587.5618;
pub const LAMBDA_F: f64 = 486.1327;
pub const LAMBDA_C: f64 = 656.2725;

/// Abbe number V_d = (n_d − 1)/(n_F − n_C) of a model.
pub fn abbe_number(m: &IorModel) -> f64 {
    (m.eta(LAMBDA_D) - 1.0) / (m.eta(LAMBDA_F) - m.eta(LAMBDA_C))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::tables::glasses;

    #[test]
    fn n_bk7_matches_catalogue() {
        let g = IorModel::glass("N-BK7").unwrap();
        assert!(
            (g.eta(LAMBDA_D) - 1.5168).abs() < 5e-5,
            "{}",
            g.eta(LAMBDA_D)
        );
        assert!(
            (abbe_number(&g) - 64.17).abs() < 0.01,
            "{}",
            abbe_number(&g)
        );
    }

    #[test]
    fn every_glass_matches_its_catalogue_and_is_sane() {
        for entry in glasses() {
            let g = IorModel::from_entry(entry);
            g.validate(360.0, 830.0).unwrap();
            assert!(
                (g.eta(LAMBDA_D) - entry.nd_catalog).abs() < 1e-4,
                "{}",
                entry.name
            );
            assert!(
                (abbe_number(&g) - entry.vd_catalog).abs() < 0.01,
                "{}",
                entry.name
            );
            // Normal dispersion: n decreases across the visible range.
            let mut prev = f64::INFINITY;
            for l in (360..=830).step_by(5) {
                let n = g.eta(l as f64);
                assert!(
                    n.is_finite() && n >= 1.0 && n < prev,
                    "{} at {l}",
                    entry.name
                );
                prev = n;
            }
        }
    }

    #[test]
    fn abbe_form_reproduces_nd_and_vd() {
        let m = IorModel::abbe(1.5, 40.0).unwrap();
        assert!((m.eta(LAMBDA_D) - 1.5).abs() < 2e-4);
        assert!((abbe_number(&m) - 40.0).abs() < 0.5, "{}", abbe_number(&m));
    }

    #[test]
    fn bad_models_are_rejected() {
        assert!(matches!(
            IorModel::glass("unobtainium"),
            Err(IorError::UnknownGlass { .. })
        ));
        assert!(IorModel::constant(0.5).is_err());
        assert!(IorModel::constant(f64::NAN).is_err());
        assert!(IorModel::abbe(1.5, 0.0).is_err());
        let pole = IorModel::Sellmeier {
            name: "pole".into(),
            b: [1.0, 0.0, 0.0],
            c: [0.25, 0.0, 0.0], // √0.25 µm = 500 nm, inside the range
        };
        assert!(pole.validate(360.0, 830.0).is_err());
    }
}
