//! The embedded reference tables (copied from `shared/data` into `assets/data`) and the
//! piecewise-linear function type they are read into.
//!
//! Every table is compiled into the binary with `include_str!`, so the program runs from
//! any directory. Parsing happens once, lazily, and is checked by the tests below.

use std::sync::OnceLock;

/// A function given by samples `(x_i, y_i)` with strictly increasing `x`, linear between
/// samples and constant beyond the ends (the convention of colour-science's Smits data).
#[derive(Clone, Debug, PartialEq)]
pub struct PiecewiseLinear {
    xs: Vec<f64>,
    ys: Vec<f64>,
}

/// Why a table could not be made into a [`PiecewiseLinear`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TableError {
    #[error("a table needs at least 2 samples, found {0}")]
    TooShort(usize),
    #[error("wavelength {value} at row {row} is not finite")]
    NonFiniteX { row: usize, value: f64 },
    #[error("value {value} at row {row} is not finite")]
    NonFiniteY { row: usize, value: f64 },
    #[error("wavelengths must increase strictly: row {row} has {value} after {previous}")]
    NotIncreasing {
        row: usize,
        value: f64,
        previous: f64,
    },
    #[error("value {value} at row {row} is negative")]
    Negative { row: usize, value: f64 },
    #[error("row {row}: {message}")]
    Parse { row: usize, message: String },
}

impl PiecewiseLinear {
    /// Builds the function, checking that `xs` increase strictly and everything is finite.
    pub fn new(xs: Vec<f64>, ys: Vec<f64>) -> Result<Self, TableError> {
        assert_eq!(xs.len(), ys.len(), "caller pairs samples");
        if xs.len() < 2 {
            return Err(TableError::TooShort(xs.len()));
        }
        for (row, (&x, &y)) in xs.iter().zip(&ys).enumerate() {
            if !x.is_finite() {
                return Err(TableError::NonFiniteX { row, value: x });
            }
            if !y.is_finite() {
                return Err(TableError::NonFiniteY { row, value: y });
            }
            if row > 0 && x <= xs[row - 1] {
                return Err(TableError::NotIncreasing {
                    row,
                    value: x,
                    previous: xs[row - 1],
                });
            }
        }
        Ok(Self { xs, ys })
    }

    pub fn xs(&self) -> &[f64] {
        &self.xs
    }

    pub fn ys(&self) -> &[f64] {
        &self.ys
    }

    /// The value at `x` (constant extrapolation outside the samples).
    pub fn eval(&self, x: f64) -> f64 {
        let n = self.xs.len();
        if x <= self.xs[0] {
            return self.ys[0];
        }
        if x >= self.xs[n - 1] {
            return self.ys[n - 1];
        }
        // First sample strictly greater than x; x lies in [xs[i-1], xs[i]).
        let i = self.xs.partition_point(|&v| v <= x);
        let (x0, x1) = (self.xs[i - 1], self.xs[i]);
        let t = (x - x0) / (x1 - x0);
        self.ys[i - 1] + t * (self.ys[i] - self.ys[i - 1])
    }

    /// The exact integral over `[a, b]` of the piecewise-linear (constant-extended) function.
    pub fn integral(&self, a: f64, b: f64) -> f64 {
        if b <= a {
            return 0.0;
        }
        // Breakpoints inside (a, b), then trapezoids between consecutive points are exact.
        let mut sum = 0.0;
        let mut x_prev = a;
        let mut y_prev = self.eval(a);
        let start = self.xs.partition_point(|&v| v <= a);
        for &x in &self.xs[start..] {
            if x >= b {
                break;
            }
            let y = self.eval(x);
            sum += 0.5 * (y + y_prev) * (x - x_prev);
            x_prev = x;
            y_prev = y;
        }
        sum + 0.5 * (self.eval(b) + y_prev) * (b - x_prev)
    }

    /// Mean value over `[a, b]`.
    pub fn average(&self, a: f64, b: f64) -> f64 {
        if b > a {
            self.integral(a, b) / (b - a)
        } else {
            self.eval(a)
        }
    }
}

/// Parses a comma-separated numeric table: `#` comment lines and one header row are
/// skipped; every remaining non-empty row must have exactly `columns` numbers.
pub fn parse_numeric_csv(text: &str, columns: usize) -> Result<Vec<Vec<f64>>, TableError> {
    let mut rows = Vec::new();
    let mut header_seen = false;
    for (line_no, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let first = line.split(',').next().unwrap_or("").trim();
        if !header_seen && first.parse::<f64>().is_err() {
            header_seen = true;
            continue;
        }
        header_seen = true;
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != columns {
            return Err(TableError::Parse {
                row: line_no + 1,
                message: format!("expected {columns} columns, found {}", fields.len()),
            });
        }
        let mut row = Vec::with_capacity(columns);
        for f in fields {
            let v: f64 = f.parse().map_err(|_| TableError::Parse {
                row: line_no + 1,
                message: format!("'{f}' is not a number"),
            })?;
            row.push(v);
        }
        rows.push(row);
    }
    Ok(rows)
}

/// The CIE 1931 2° colour-matching functions, 360–830 nm at 1 nm.
pub struct Cmf {
    pub x: PiecewiseLinear,
    pub y: PiecewiseLinear,
    pub z: PiecewiseLinear,
}

/// The lowest and highest wavelengths (nm) the colour-matching tables cover.
pub const CMF_RANGE: (f64, f64) = (360.0, 830.0);

fn columns_of(text: &str, columns: usize) -> Vec<PiecewiseLinear> {
    let rows = parse_numeric_csv(text, columns).expect("embedded table parses");
    let xs: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    (1..columns)
        .map(|c| {
            PiecewiseLinear::new(xs.clone(), rows.iter().map(|r| r[c]).collect())
                .expect("embedded table is valid")
        })
        .collect()
}

pub fn cmf() -> &'static Cmf {
    static CMF: OnceLock<Cmf> = OnceLock::new();
    CMF.get_or_init(|| {
        let mut cols = columns_of(
            include_str!("../../../assets/data/cie1931_2deg_cmf_1nm.csv"),
            4,
        )
        .into_iter();
        Cmf {
            x: cols.next().expect("x column"),
            y: cols.next().expect("y column"),
            z: cols.next().expect("z column"),
        }
    })
}

/// CIE illuminant D65, relative (100 at 560 nm), 360–830 nm at 1 nm.
pub fn d65() -> &'static PiecewiseLinear {
    static D65: OnceLock<PiecewiseLinear> = OnceLock::new();
    D65.get_or_init(|| {
        columns_of(include_str!("../../../assets/data/cie_d65_1nm.csv"), 2)
            .pop()
            .expect("d65 column")
    })
}

/// CIE illuminant F11 (narrow-band fluorescent), relative, 380–780 nm at 5 nm.
pub fn fl11() -> &'static PiecewiseLinear {
    static FL11: OnceLock<PiecewiseLinear> = OnceLock::new();
    FL11.get_or_init(|| {
        columns_of(include_str!("../../../assets/data/cie_fl11_5nm.csv"), 2)
            .pop()
            .expect("fl11 column")
    })
}

/// Smits' seven basis spectra, in the order white, cyan, magenta, yellow, red, green, blue.
pub fn smits_basis() -> &'static [PiecewiseLinear; 7] {
    static BASIS: OnceLock<[PiecewiseLinear; 7]> = OnceLock::new();
    BASIS.get_or_init(|| {
        let text = include_str!("../../../assets/data/smits1999_basis.csv");
        let rows = parse_numeric_csv(text, 8).expect("embedded table parses");
        // colour-science stores the positions to 4 decimals; the exact ones are 380 + i·340/9.
        let xs: Vec<f64> = (0..rows.len())
            .map(|i| 380.0 + i as f64 * 340.0 / 9.0)
            .collect();
        std::array::from_fn(|c| {
            PiecewiseLinear::new(xs.clone(), rows.iter().map(|r| r[c + 1]).collect())
                .expect("embedded table is valid")
        })
    })
}

/// One row of the embedded Sellmeier glass table.
#[derive(Clone, Debug, PartialEq)]
pub struct GlassEntry {
    pub name: String,
    pub b: [f64; 3],
    /// Resonance terms in µm².
    pub c: [f64; 3],
    pub nd_catalog: f64,
    pub vd_catalog: f64,
}

pub fn glasses() -> &'static [GlassEntry] {
    static GLASSES: OnceLock<Vec<GlassEntry>> = OnceLock::new();
    GLASSES.get_or_init(|| {
        let text = include_str!("../../../assets/data/glass_sellmeier.csv");
        text.lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("glass,") && !l.trim().is_empty())
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                let num = |i: usize| f[i].trim().parse::<f64>().expect("embedded glass number");
                GlassEntry {
                    name: f[0].to_string(),
                    b: [num(1), num(2), num(3)],
                    c: [num(4), num(5), num(6)],
                    nd_catalog: num(7),
                    vd_catalog: num(8),
                }
            })
            .collect()
    })
}

/// Finds a glass by name, ignoring case and treating `-`, `_` and spaces alike
/// (`"N-BK7"`, `"n_bk7"`, `"fused silica"` all work).
pub fn find_glass(name: &str) -> Option<&'static GlassEntry> {
    let key = |s: &str| {
        s.chars()
            .filter(|c| !matches!(c, '-' | '_' | ' '))
            .flat_map(char::to_lowercase)
            .collect::<String>()
    };
    let wanted = key(name);
    glasses().iter().find(|g| key(&g.name) == wanted)
}

/// The names of the embedded glasses, for error messages and the UI.
pub fn glass_names() -> Vec<&'static str> {
    glasses().iter().map(|g| g.name.as_str()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cmf_table_matches_documented_sum() {
        // shared/data/README.md: Σ ȳ over the 471 one-nanometre rows = 106.8569.
        let sum: f64 = cmf().y.ys().iter().sum();
        assert!((sum - 106.8569).abs() < 1e-3, "sum ȳ = {sum}");
        assert_eq!(cmf().y.xs().len(), 471);
    }

    #[test]
    fn integral_of_piecewise_linear_is_exact() {
        let f = PiecewiseLinear::new(vec![0.0, 1.0, 3.0], vec![0.0, 2.0, 0.0]).unwrap();
        assert!((f.integral(0.0, 3.0) - 3.0).abs() < 1e-12);
        assert!((f.integral(0.5, 2.0) - 2.25).abs() < 1e-12);
        // Constant extension outside the samples.
        assert!((f.integral(-1.0, 0.0)).abs() < 1e-12);
        assert!((f.integral(3.0, 5.0)).abs() < 1e-12);
    }

    #[test]
    fn tables_reject_bad_rows() {
        assert!(matches!(
            PiecewiseLinear::new(vec![1.0, 1.0], vec![0.0, 0.0]),
            Err(TableError::NotIncreasing { .. })
        ));
        assert!(matches!(
            PiecewiseLinear::new(vec![1.0], vec![0.0]),
            Err(TableError::TooShort(1))
        ));
        assert!(matches!(
            PiecewiseLinear::new(vec![1.0, 2.0], vec![f64::NAN, 0.0]),
            Err(TableError::NonFiniteY { .. })
        ));
        assert!(parse_numeric_csv("a,b\n1,2,3\n", 2).is_err());
    }

    #[test]
    fn glasses_are_found_by_loose_names() {
        assert_eq!(find_glass("n-bk7").unwrap().name, "N-BK7");
        assert_eq!(find_glass("fused silica").unwrap().name, "fused_silica");
        assert!(find_glass("unobtainium").is_none());
        assert_eq!(glass_names().len(), 5);
    }
}
