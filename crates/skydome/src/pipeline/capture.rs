//! When and where the bracket was taken, and where each of the two came from: the capture time
//! from EXIF `DateTimeOriginal` with `OffsetTimeOriginal` (or the given
//! [`SkyOptions::time_zone`](super::SkyOptions::time_zone) for a camera that writes no offset),
//! or a time given outright; the site from EXIF GPS or given. The ephemeris, the header's
//! `CAPDATE=`/`GMT=`/`#SITE=` lines and the report's [`CaptureReport`] all read this one answer.

use serde::{Deserialize, Serialize};
use time::{OffsetDateTime, PrimitiveDateTime, UtcOffset};

use super::{Options, PipelineError};
use crate::bracket::{self, format_exif_datetime, format_iso8601_utc, Bracket};

/// Where a capture's time or site came from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Provenance {
    /// The photos' EXIF (`DateTimeOriginal` + `OffsetTimeOriginal`, or GPS).
    #[serde(rename = "exif")]
    Exif,
    /// EXIF's clock read in the given time zone ([`SkyOptions::time_zone`](super::SkyOptions::time_zone)).
    #[serde(rename = "exif+flag")]
    ExifClockGivenZone,
    /// Given by the caller (a command-line flag, an option).
    #[serde(rename = "flag")]
    Given,
    /// Not known.
    #[default]
    #[serde(rename = "none")]
    None,
}

impl Provenance {
    /// The report's word: `exif`, `exif+flag`, `flag` or `none`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Exif => "exif",
            Self::ExifClockGivenZone => "exif+flag",
            Self::Given => "flag",
            Self::None => "none",
        }
    }
}

/// When and where, as the report gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureReport {
    /// The capture instant in UTC, ISO 8601 (`2026-06-21T07:00:00Z`), when known.
    pub time_utc: Option<String>,
    /// Where the time came from.
    pub time_from: Provenance,
    /// Latitude, degrees, north positive.
    pub latitude_deg: Option<f64>,
    /// Longitude, degrees, east positive.
    pub longitude_deg: Option<f64>,
    /// Where the site came from (`flag` when either coordinate was given).
    pub site_from: Provenance,
}

/// The resolved capture context.
#[derive(Debug, Clone)]
pub(super) struct Capture {
    /// The capture instant.
    pub time: Option<OffsetDateTime>,
    /// The local wall-clock time (`CAPDATE=`), when known.
    pub local: Option<PrimitiveDateTime>,
    /// Latitude and longitude, degrees, when both are known.
    pub site: Option<(f64, f64)>,
    /// The same for the report.
    pub report: CaptureReport,
}

/// Resolves time and site: a given time wins; otherwise EXIF's clock with the given time zone,
/// else with EXIF's own offset; a given coordinate wins over EXIF GPS.
pub(super) fn resolve(o: &Options, br: &Bracket) -> Result<Capture, PipelineError> {
    let info = &br.info;
    let exif_local = info
        .datetime_original
        .as_deref()
        .and_then(bracket::parse_exif_datetime);
    let zone = match &o.sky.time_zone {
        Some(z) => Some(
            bracket::parse_utc_offset(z).ok_or_else(|| PipelineError::BadTimeZone(z.clone()))?,
        ),
        None => None,
    };
    let exif_offset = info
        .utc_offset
        .as_deref()
        .and_then(bracket::parse_utc_offset);
    let (time, local, time_from) = match &o.sky.time {
        Some(t) => {
            let t = bracket::parse_iso8601(t).ok_or_else(|| PipelineError::BadTime(t.clone()))?;
            (
                Some(t),
                Some(PrimitiveDateTime::new(t.date(), t.time())),
                Provenance::Given,
            )
        }
        None => match (exif_local, zone, exif_offset) {
            (Some(l), Some(z), _) => (
                Some(l.assume_offset(z)),
                Some(l),
                Provenance::ExifClockGivenZone,
            ),
            (Some(l), None, Some(z)) => (Some(l.assume_offset(z)), Some(l), Provenance::Exif),
            (l, _, _) => (None, l, Provenance::None),
        },
    };
    let lat = o.sky.latitude_deg.or(info.gps_latitude_deg);
    let lon = o.sky.longitude_deg.or(info.gps_longitude_deg);
    let site = lat.zip(lon);
    let site_from = match (
        site,
        o.sky.latitude_deg.is_some() || o.sky.longitude_deg.is_some(),
    ) {
        (None, _) => Provenance::None,
        (Some(_), true) => Provenance::Given,
        (Some(_), false) => Provenance::Exif,
    };
    Ok(Capture {
        time,
        local,
        site,
        report: CaptureReport {
            time_utc: time.map(format_iso8601_utc),
            time_from,
            latitude_deg: site.map(|s| s.0),
            longitude_deg: site.map(|s| s.1),
            site_from,
        },
    })
}

impl Capture {
    /// `CAPDATE=` (local) and `GMT=` (UTC) for the Radiance header, `YYYY:MM:DD HH:MM:SS`.
    pub fn header_times(&self) -> (Option<String>, Option<String>) {
        let f = format_exif_datetime;
        let gmt = self.time.map(|t| {
            let u = t.to_offset(UtcOffset::UTC);
            f(PrimitiveDateTime::new(u.date(), u.time()))
        });
        (self.local.map(f), gmt)
    }

    /// The header's site line: `#SITE= <latitude> <longitude>` in degrees (north and east
    /// positive), and where it came from.
    pub fn site_line(&self) -> Option<String> {
        let (lat, lon) = self.site?;
        Some(format!(
            "#SITE= {lat:.6} {lon:.6} (latitude N, longitude E, degrees; from {})",
            self.report.site_from.name()
        ))
    }
}
