//! Byte layouts of stored photons.
//!
//! Every stored photon is a 16-byte [`PhotonHeader`] plus its flux, kept in two parallel
//! arrays (structure of arrays), plus one byte of kd-tree split axis:
//!
//! | storage   | header                         | flux                              | kd axis | bytes/photon |
//! |-----------|--------------------------------|-----------------------------------|---------|--------------|
//! | `full`    | position 3×f32, normal u32     | N × f32                           | u8      | 17 + 4N      |
//! | `compact` | position 3×f32, normal u32     | 3 × f32: RGB triplet or spike     | u8      | 29           |
//! | `rgb`     | position 3×f32, normal u32     | 3 × f32: linear sRGB              | u8      | 29           |
//! | `packed`  | position 3×f32, normal u16     | u32: packed triplet or spike      | u8      | 19           |
//! | `spiked`  | position 3×f32, normal u32     | 3 × f32 compact + bin, amplitude  | u8      | 37           |
//!
//! `packed` is `compact` in 32 bits (issue #14): a triplet as three 8-bit mantissas under
//! one 7-bit shared exponent (2⁻⁶⁴…2⁶³, within 0.2 % of the largest channel), a spike as
//! its 12-bit bin and a 7 + 12-bit float amplitude (within 1.3·10⁻⁴), the top bit telling
//! them apart; the normal in 2×8-bit octahedral code (within 1.5°, against the 37° a
//! density estimate allows).
//!
//! `spiked` (issue #14) is `compact` plus one exact spike: a photon whose spectrum has a
//! narrow peak (a fluorescent lamp's lines) keeps the strongest bin's excess over its
//! neighbours as `(bin, amplitude)` and the rest as the triplet — only where that decodes
//! closer to the photon's flux than the triplet alone; else the spike's amplitude is 0.
//!
//! The normal is the landing surface's normal on the side the photon arrived from,
//! octahedral-encoded in 2×16 bits (error < 0.01°). Lambertian surfaces need no incoming
//! direction; the normal lets a density estimate keep only photons of the query's own
//! surface and side (no leaks through thin walls, round corners or onto the back face). A compact **spike** record is `(-1.0, bin as f32, amplitude)`: lossless, since
//! a valid RGB triplet is never negative and an f32 holds every bin index exactly.

use glam::Vec3;

use crate::spectral::Transport;

/// What the user chooses: the paper's three configurations. Each is a light transport
/// (N spectral bins, or three RGB channels) paired with a record format; the tracer and
/// the maps only see the two halves ([`Storage::transport`], [`Storage::record`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Storage {
    /// Spectral transport, N floats per photon.
    Full,
    /// Spectral transport, Lai & Christensen's Algorithm 1: RGB triplet or lossless spike.
    Compact,
    /// Compact records packed into 32 bits (19 bytes a photon with its position, normal
    /// and kd byte): quantised triplet and spike amplitude.
    Packed,
    /// Compact records plus one exact spike beside the triplet (see the module notes).
    Spiked,
    /// The RGB renderer baseline: transport and storage in linear sRGB.
    Rgb,
}

/// How a photon's flux is kept in a map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Record {
    /// Every channel as an f32 (N bins, or the three RGB channels).
    Full,
    /// Three f32: a triplet of the flux's colour — the paper's Smits triplet on grids with
    /// Smits scene colours, else the linear-sRGB colour, decoded by Jakob–Hanika (see
    /// [`crate::spectral::BinGrid::encode_triplet`]) — or the spike `(-1, bin, amplitude)`
    /// for a single-bin flux. Needs a spectral grid.
    Compact,
    /// A compact record packed into one u32 (see [`pack_record`]), the normal in 16 bits.
    Packed,
    /// Five f32: a compact record, then a spike's bin (as f32) and amplitude (0: none).
    Spiked,
}

/// Bytes of a packed photon: position 12, normal 2, record 4, kd axis 1.
pub const PACKED_BYTES: usize = 12 + 2 + 4 + 1;
const _: () = assert!(PACKED_BYTES <= 20);

impl Record {
    /// f32 flux values per photon for a grid of `channels` channels.
    pub fn flux_stride(self, channels: usize) -> usize {
        match self {
            Record::Full => channels,
            Record::Compact => 3,
            Record::Spiked => 5,
            Record::Packed => 0,
        }
    }

    /// Exact bytes per stored photon (header + flux + kd axis byte).
    pub fn bytes_per_photon(self, channels: usize) -> usize {
        match self {
            Record::Packed => PACKED_BYTES,
            _ => size_of::<PhotonHeader>() + 4 * self.flux_stride(channels) + 1,
        }
    }
}

impl Storage {
    pub fn name(self) -> &'static str {
        match self {
            Storage::Full => "full",
            Storage::Compact => "compact",
            Storage::Rgb => "rgb",
            Storage::Packed => "packed",
            Storage::Spiked => "spiked",
        }
    }

    pub const ALL: [Storage; 5] = [
        Storage::Full,
        Storage::Compact,
        Storage::Packed,
        Storage::Spiked,
        Storage::Rgb,
    ];

    pub fn transport(self) -> Transport {
        match self {
            Storage::Full | Storage::Compact | Storage::Packed | Storage::Spiked => {
                Transport::Spectral
            }
            Storage::Rgb => Transport::Rgb,
        }
    }

    pub fn record(self) -> Record {
        match self {
            Storage::Full | Storage::Rgb => Record::Full,
            Storage::Compact => Record::Compact,
            Storage::Packed => Record::Packed,
            Storage::Spiked => Record::Spiked,
        }
    }

    /// Channels light is carried in when the user asks for `bins` bins (RGB: always 3).
    pub fn channels(self, bins: usize) -> usize {
        match self.transport() {
            Transport::Spectral => bins,
            Transport::Rgb => 3,
        }
    }

    /// Exact bytes per stored photon at `bins` bins (header + flux + kd axis byte).
    pub fn bytes_per_photon(self, bins: usize) -> usize {
        self.record().bytes_per_photon(self.channels(bins))
    }
}

impl std::str::FromStr for Storage {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "full" => Ok(Storage::Full),
            "compact" => Ok(Storage::Compact),
            "rgb" => Ok(Storage::Rgb),
            "packed" => Ok(Storage::Packed),
            "spiked" => Ok(Storage::Spiked),
            _ => Err(format!(
                "unknown storage '{s}' (use full, compact, packed, spiked or rgb)"
            )),
        }
    }
}

/// Position and surface normal of a stored photon: 16 bytes. The normal is the landing
/// surface's geometric normal turned towards the side the photon came from: a density
/// estimate counts a photon only on the same side of the same surface as the query, which
/// keeps light from leaking through thin walls and round corners.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotonHeader {
    pub pos: [f32; 3],
    pub normal: u32,
}

const _: () = assert!(size_of::<PhotonHeader>() == 16);

/// A unit normal as photon records store it: its octahedral code ([`oct_encode`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NormalCode(pub u32);

impl From<Vec3> for NormalCode {
    #[inline]
    fn from(n: Vec3) -> Self {
        Self(oct_encode(n))
    }
}

impl PhotonHeader {
    pub fn new(pos: Vec3, normal: impl Into<NormalCode>) -> Self {
        Self {
            pos: pos.to_array(),
            normal: normal.into().0,
        }
    }

    #[inline]
    pub fn position(&self) -> Vec3 {
        Vec3::from_array(self.pos)
    }

    #[inline]
    pub fn normal(&self) -> Vec3 {
        oct_decode(self.normal)
    }
}

/// The marker in the first float of a spike record.
pub const SPIKE_MARKER: f32 = -1.0;

/// A compact spike record for `amplitude` in `bin`.
#[inline]
pub fn encode_spike(bin: usize, amplitude: f32) -> [f32; 3] {
    [SPIKE_MARKER, bin as f32, amplitude]
}

/// `(bin, amplitude)` if the compact record is a spike.
#[inline]
pub fn decode_spike(rec: [f32; 3]) -> Option<(usize, f32)> {
    (rec[0] < 0.0).then_some((rec[1] as usize, rec[2]))
}

const PACK_SPIKE: u32 = 1 << 31;
const EXP_BIAS: i32 = 64;

/// 2^e as an f32 for e in −126…127 (0 below, ∞ above).
#[inline]
fn exp2i(e: i32) -> f32 {
    if e < -126 {
        0.0
    } else if e > 127 {
        f32::INFINITY
    } else {
        f32::from_bits(((e + 127) as u32) << 23)
    }
}

/// A compact record (triplet ≥ 0, or spike) in 32 bits. Triplet: bit 31 clear, a 7-bit
/// exponent E (bias 64) and three 8-bit mantissas mᵢ: cᵢ = mᵢ·2^(E−64−8), E chosen so the
/// largest channel's mantissa is 128–255 (rounded to nearest). Spike: bit 31 set, bin in
/// bits 19–30, amplitude as a 7-bit exponent (bias 64) and a 12-bit mantissa with a
/// hidden one. Values beyond 2⁶³ saturate; below 2⁻⁶⁴ they round to 0.
pub fn pack_record(rec: [f32; 3]) -> u32 {
    if let Some((bin, a)) = decode_spike(rec) {
        let bin = (bin as u32).min(0xFFF);
        if !(a > 0.0) {
            return PACK_SPIKE | (bin << 19);
        }
        let mut e = a.log2().floor() as i32;
        let mut m = ((a / exp2i(e) - 1.0) * 4096.0).round() as i32;
        if m >= 4096 {
            m = 0;
            e += 1;
        }
        if e + EXP_BIAS < 0 {
            return PACK_SPIKE | (bin << 19);
        }
        let (e, m) = if e + EXP_BIAS > 127 {
            (127 - EXP_BIAS, 4095)
        } else {
            (e, m)
        };
        return PACK_SPIKE | (bin << 19) | (((e + EXP_BIAS) as u32) << 12) | m as u32;
    }
    let rec = rec.map(|c| if c > 0.0 && c.is_finite() { c } else { 0.0 });
    let peak = rec[0].max(rec[1]).max(rec[2]);
    if peak <= 0.0 {
        return 0;
    }
    // peak in [2^(E−1), 2^E): its mantissa peak·2^(8−E) in [128, 256).
    let mut e = peak.log2().floor() as i32 + 1;
    let quant = |e: i32| rec.map(|c| (c * exp2i(8 - e)).round() as u32);
    let mut m = quant(e);
    if m.iter().any(|&v| v > 255) {
        e += 1;
        m = quant(e);
    }
    if e + EXP_BIAS < 0 {
        return 0;
    }
    if e + EXP_BIAS > 127 {
        return (127 << 24) | 0xFF_FFFF;
    }
    (((e + EXP_BIAS) as u32) << 24) | (m[0].min(255) << 16) | (m[1].min(255) << 8) | m[2].min(255)
}

/// The compact record a packed word holds (a triplet, or the spike `(-1, bin, amplitude)`).
#[inline]
pub fn unpack_record(w: u32) -> [f32; 3] {
    if w & PACK_SPIKE != 0 {
        let bin = (w >> 19) & 0xFFF;
        let e = ((w >> 12) & 0x7F) as i32 - EXP_BIAS;
        let m = w & 0xFFF;
        let a = if w & 0x7FFFF == 0 {
            0.0
        } else {
            exp2i(e) * (1.0 + m as f32 / 4096.0)
        };
        return encode_spike(bin as usize, a);
    }
    let k = exp2i(((w >> 24) & 0x7F) as i32 - EXP_BIAS - 8);
    [
        ((w >> 16) & 0xFF) as f32 * k,
        ((w >> 8) & 0xFF) as f32 * k,
        (w & 0xFF) as f32 * k,
    ]
}

/// A 2×16-bit octahedral code rounded to 2×8 bits (the packed record's normal).
#[inline]
pub fn oct_to_16(e: u32) -> u16 {
    let q = |v: u32| ((v as f32 / 65535.0 * 255.0).round() as u16).min(255);
    q(e & 0xFFFF) | (q(e >> 16) << 8)
}

/// The 2×16-bit code of a 2×8-bit one.
#[inline]
pub fn oct_from_16(c: u16) -> u32 {
    let u = (c & 0xFF) as u32 * 257;
    let v = (c >> 8) as u32 * 257;
    u | (v << 16)
}

/// Octahedral encoding of a unit vector in 2×16 bits.
pub fn oct_encode(d: Vec3) -> u32 {
    let d = d.normalize_or_zero();
    let l1 = d.x.abs() + d.y.abs() + d.z.abs();
    if l1 == 0.0 {
        return 0;
    }
    let (mut u, mut v) = (d.x / l1, d.y / l1);
    if d.z < 0.0 {
        let (pu, pv) = (u, v);
        u = (1.0 - pv.abs()) * pu.signum();
        v = (1.0 - pu.abs()) * pv.signum();
    }
    let q = |x: f32| round_unit16((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65535.0);
    q(u) | (q(v) << 16)
}

/// `w.round() as u32 & 0xFFFF` for `w` in [0, 65535] (and 0 for NaN) without the libm
/// call `round` compiles to on baseline x86-64: w + ½ is exact in f64 and, being
/// non-negative, truncates to the same integer as rounding half away from zero.
#[inline]
fn round_unit16(w: f32) -> u32 {
    ((w as f64 + 0.5) as u32) & 0xFFFF
}

pub fn oct_decode(e: u32) -> Vec3 {
    oct_unnormalized(e).normalize_or_zero()
}

/// The decoded direction before normalisation (length between 1/√3 and 1): enough for
/// a sign or an angle test, without the square root.
#[inline]
pub fn oct_unnormalized(e: u32) -> Vec3 {
    let u = (e & 0xFFFF) as f32 / 65535.0 * 2.0 - 1.0;
    let v = (e >> 16) as f32 / 65535.0 * 2.0 - 1.0;
    let z = 1.0 - u.abs() - v.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - v.abs()) * u.signum(), (1.0 - u.abs()) * v.signum())
    } else {
        (u, v)
    };
    Vec3::new(x, y, z)
}

/// Whether the encoded unit vector `e` is within acos(`min_cos`) of unit `n`
/// (`min_cos` > 0), without normalising it.
#[inline]
pub fn oct_within(e: u32, n: Vec3, min_cos: f32) -> bool {
    let v = oct_unnormalized(e);
    let d = v.dot(n);
    d > 0.0 && d * d >= min_cos * min_cos * v.length_squared()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng, uniform_sphere};

    #[test]
    fn the_quantiser_rounds_as_f32_round_does() {
        // Every value a half apart over the range, the halves' neighbours, and NaN.
        let check = |w: f32| assert_eq!(round_unit16(w), (w.round() as u32) & 0xFFFF, "{w}");
        for i in 0..=2 * 65535u32 {
            let w = i as f32 * 0.5;
            check(w);
            check(f32::from_bits(w.to_bits() + 1));
            if w > 0.0 {
                check(f32::from_bits(w.to_bits() - 1));
            }
        }
        check(f32::NAN);
    }

    #[test]
    fn spike_round_trip_is_exact_for_every_bin_and_amplitude() {
        for n in [1usize, 2, 4, 100, 1000] {
            for bin in 0..n {
                for amp in [
                    f32::from_bits(1), // smallest denormal
                    f32::MIN_POSITIVE,
                    1e-20,
                    0.37,
                    1.0,
                    12345.678,
                    1e30,
                ] {
                    let rec = encode_spike(bin, amp);
                    assert_eq!(decode_spike(rec), Some((bin, amp)));
                }
            }
        }
        // A valid RGB triplet is never mistaken for a spike.
        assert_eq!(decode_spike([0.0, 5.0, 1.0]), None);
    }

    #[test]
    fn packed_records_round_trip_within_their_precision() {
        let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
        for scale in [1e-15f32, 1e-6, 1e-3, 1.0, 37.0, 1e6, 1e18] {
            for _ in 0..2_000 {
                let [a, b] = rng.next_2d();
                let [c, _] = rng.next_2d();
                let rec = [a * scale, b * scale * 0.3, c * c * scale];
                let back = unpack_record(pack_record(rec));
                let peak = rec[0].max(rec[1]).max(rec[2]);
                for k in 0..3 {
                    assert!(
                        (back[k] - rec[k]).abs() <= peak * (0.5 / 128.0) * 1.01,
                        "{rec:?} → {back:?}"
                    );
                }
            }
        }
        assert_eq!(unpack_record(pack_record([0.0; 3])), [0.0; 3]);
        for bin in [0usize, 1, 99, 999, 4095] {
            for amp in [1e-18f32, 1e-5, 0.37, 1.0, 12345.678, 1e18] {
                let (b, a) = decode_spike(unpack_record(pack_record(encode_spike(bin, amp))))
                    .expect("a spike stays a spike");
                assert_eq!(b, bin);
                assert!(((a - amp) / amp).abs() <= 1.25e-4, "{amp} → {a}");
            }
        }
        // Normals to 8 bits a component: within 1.5°.
        for _ in 0..10_000 {
            let d = uniform_sphere(rng.next_2d());
            let back = oct_decode(oct_from_16(oct_to_16(oct_encode(d))));
            assert!(d.dot(back) > 1.5f32.to_radians().cos(), "{d} {back}");
        }
    }

    #[test]
    fn storage_sizes_are_as_documented() {
        assert_eq!(Storage::Packed.bytes_per_photon(4), 19);
        assert_eq!(Storage::Packed.bytes_per_photon(4096), 19);
        assert_eq!(Storage::Compact.bytes_per_photon(4), 29);
        assert_eq!(Storage::Compact.bytes_per_photon(1000), 29);
        assert_eq!(Storage::Rgb.bytes_per_photon(100), 29);
        assert_eq!(Storage::Full.bytes_per_photon(4), 33);
        assert_eq!(Storage::Full.bytes_per_photon(100), 417);
    }

    #[test]
    fn octahedral_directions_are_accurate() {
        let mut rng = Rng::stream(0, 0, 0, Purpose::Photon);
        for _ in 0..10_000 {
            let d = uniform_sphere(rng.next_2d());
            let back = oct_decode(oct_encode(d));
            // Angle from |d × back| (a dot product near 1 has no f32 resolution left).
            assert!(
                d.cross(back).length() < 0.01f32.to_radians().sin(),
                "{d} {back}"
            );
        }
        for d in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            assert!(d.dot(oct_decode(oct_encode(d))) > 0.9999);
        }
    }
}
