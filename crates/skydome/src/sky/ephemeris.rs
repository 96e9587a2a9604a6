//! The sun's computed position (NREL SPA) and its comparison with a detected sun.

use serde::{Deserialize, Serialize};
use time::OffsetDateTime;

use super::{Direction, SkyError};

/// Atmospheric refraction applied to the computed sun (the photo shows the refracted, apparent
/// sun; refraction lifts it by ≈0.5° at the horizon and ≈0.01° at 45°).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Refraction {
    /// Geometric (true) position, no refraction.
    None,
    /// Standard atmosphere: 1013.25 hPa, 15 °C.
    #[default]
    Standard,
    /// Given conditions.
    Atmosphere {
        /// Pressure in hPa (millibar), (0, 2000].
        pressure_hpa: f64,
        /// Air temperature in °C, (−273, 100].
        temperature_c: f64,
    },
}

/// Where the photos were taken.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Site {
    /// Latitude in degrees, north positive, `[−90, 90]`.
    pub latitude_deg: f64,
    /// Longitude in degrees, east positive, `[−180, 180]`.
    pub longitude_deg: f64,
    /// Height above sea level in metres (parallax only).
    pub height_m: f64,
    /// Refraction model.
    pub refraction: Refraction,
}

/// The sun's topocentric direction at `time` (any UTC offset; converted to UTC) seen from
/// `site`, by NREL SPA. `delta_t_s` is TT − UT1 in seconds; `None` uses the Espenak–Meeus
/// estimate for the year (off by at most a few seconds for recent years, which moves the sun by
/// under 0.0001°).
pub fn sun_ephemeris(
    time: OffsetDateTime,
    site: &Site,
    delta_t_s: Option<f64>,
) -> Result<Direction, SkyError> {
    use solar_positioning::{time::JulianDate, Location, RefractionCorrection, SolarPositions};
    let utc = time.to_offset(time::UtcOffset::UTC);
    let second = f64::from(utc.second()) + f64::from(utc.nanosecond()) * 1e-9;
    let delta_t = match delta_t_s {
        Some(d) => d,
        None => {
            let year = f64::from(utc.year()) + (f64::from(utc.ordinal()) - 0.5) / 365.25;
            solar_positioning::delta_t::estimate(year)
                .map_err(|e| SkyError::Ephemeris(e.to_string()))?
        }
    };
    let jd = JulianDate::from_utc(
        utc.year(),
        u32::from(u8::from(utc.month())),
        u32::from(utc.day()),
        u32::from(utc.hour()),
        u32::from(utc.minute()),
        second,
        delta_t,
    )
    .map_err(|e| SkyError::Ephemeris(e.to_string()))?;
    let refraction = match site.refraction {
        Refraction::None => None,
        Refraction::Standard => Some(RefractionCorrection::standard()),
        Refraction::Atmosphere {
            pressure_hpa,
            temperature_c,
        } => Some(
            RefractionCorrection::new(pressure_hpa, temperature_c)
                .map_err(|e| SkyError::Ephemeris(e.to_string()))?,
        ),
    };
    let pos = SolarPositions::new()
        .at_from_julian(
            jd,
            Location {
                latitude: site.latitude_deg,
                longitude: site.longitude_deg,
            },
            site.height_m,
            refraction,
        )
        .map_err(|e| SkyError::Ephemeris(e.to_string()))?;
    Ok(Direction::new(pos.azimuth(), 90.0 - pos.zenith_angle()))
}

/// Agreement between a detected (or tapped) sun and the computed one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SunCrossCheck {
    /// Great-circle angle between the two, degrees.
    pub angle_deg: f64,
    /// `computed − detected` azimuth wrapped to `(−180, 180]` degrees: add it to the compass
    /// (north) azimuth to make the azimuths agree.
    pub compass_error_deg: f64,
    /// `computed − detected` elevation, degrees (a tilted phone or a wrong lens model shows here).
    pub elevation_error_deg: f64,
}

/// Compares a detected sun with the ephemeris sun (see the module docs).
pub fn cross_check(detected: &Direction, computed: &Direction) -> SunCrossCheck {
    let mut d = (computed.azimuth_deg - detected.azimuth_deg).rem_euclid(360.0);
    if d > 180.0 {
        d -= 360.0;
    }
    SunCrossCheck {
        angle_deg: detected.angle_to(computed),
        compass_error_deg: d,
        elevation_error_deg: computed.elevation_deg - detected.elevation_deg,
    }
}
