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
}

impl Record {
    /// f32 flux values per photon for a grid of `channels` channels.
    pub fn flux_stride(self, channels: usize) -> usize {
        match self {
            Record::Full => channels,
            Record::Compact => 3,
        }
    }

    /// Exact bytes per stored photon (header + flux + kd axis byte).
    pub fn bytes_per_photon(self, channels: usize) -> usize {
        size_of::<PhotonHeader>() + 4 * self.flux_stride(channels) + 1
    }
}

impl Storage {
    pub fn name(self) -> &'static str {
        match self {
            Storage::Full => "full",
            Storage::Compact => "compact",
            Storage::Rgb => "rgb",
        }
    }

    pub const ALL: [Storage; 3] = [Storage::Full, Storage::Compact, Storage::Rgb];

    pub fn transport(self) -> Transport {
        match self {
            Storage::Full | Storage::Compact => Transport::Spectral,
            Storage::Rgb => Transport::Rgb,
        }
    }

    pub fn record(self) -> Record {
        match self {
            Storage::Full | Storage::Rgb => Record::Full,
            Storage::Compact => Record::Compact,
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
            _ => Err(format!("unknown storage '{s}' (use full, compact or rgb)")),
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

impl PhotonHeader {
    pub fn new(pos: Vec3, normal: Vec3) -> Self {
        Self {
            pos: pos.to_array(),
            normal: oct_encode(normal),
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
    let q = |x: f32| (((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65535.0).round() as u32) & 0xFFFF;
    q(u) | (q(v) << 16)
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
    fn storage_sizes_are_as_documented() {
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
