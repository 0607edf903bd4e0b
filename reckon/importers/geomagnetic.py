"""The undisturbed Earth field at a place and date, from the World Magnetic Model (pygeomag).

For a venue whose floor plan is geo-referenced (ILC's GeoJSON is in longitude/latitude, east to
+x and north to +y after reckon.importers.ilc_plan.read_floor_plan), this gives the venue's
`magnetic_north_deg`, `magnetic_field_ut` and `magnetic_dip_deg` (protocol/session.py): what a
phone's magnetometer should read where the building does not bend the field.
"""

from __future__ import annotations

import datetime as dt

from pygeomag import GeoMag

NT_PER_UT = 1000.0


def decimal_year(unix_ns: int) -> float:
    moment = dt.datetime.fromtimestamp(unix_ns * 1e-9, dt.timezone.utc)
    start = dt.datetime(moment.year, 1, 1, tzinfo=dt.timezone.utc)
    end = dt.datetime(moment.year + 1, 1, 1, tzinfo=dt.timezone.utc)
    return moment.year + (moment - start) / (end - start)


def venue_field(latitude_deg: float, longitude_deg: float, unix_ns: int, north_deg: float = 90.0) -> dict[str, float]:
    """Venue keys for a place and time. `north_deg`: true north's direction in the venue frame
    (counter-clockwise from +x). WMM's declination is positive east of true north, so magnetic
    north lies `declination` clockwise of true north. Dates outside the model's five years are
    extrapolated (its error then grows by about 0.1 deg a year)."""
    year = decimal_year(unix_ns)
    epoch = "2015v2" if year < 2020 else "2020" if year < 2025 else "2025"
    model = GeoMag(coefficients_file=f"wmm/WMM_{epoch}.COF")
    field = model.calculate(glat=latitude_deg, glon=longitude_deg, alt=0.0, time=year,
                            allow_date_outside_lifespan=True)
    return {"magnetic_north_deg": round(north_deg - field.d, 3), "magnetic_field_ut": round(field.f / NT_PER_UT, 2),
            "magnetic_dip_deg": round(field.i, 3)}
