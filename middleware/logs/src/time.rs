//! Calendar arithmetic in UTC and exact decimal seconds: enough for BLF start dates, ASC
//! header dates and recording file names, without a date crate and without floats.

/// Days from 1970-01-01 to this proleptic Gregorian date (the well-known era-based
/// conversion: 400-year eras of 146097 days, years starting in March).
pub(crate) fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(month);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The date of a day counted from 1970-01-01: (year, month 1-12, day 1-31).
pub(crate) fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

fn days_in_month(year: i64, month: u32) -> u32 {
    match month {
        4 | 6 | 9 | 11 => 30,
        2 if (year % 4 == 0 && year % 100 != 0) || year % 400 == 0 => 29,
        2 => 28,
        _ => 31,
    }
}

/// A UTC date and time broken down, to the microsecond.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Utc {
    /// Year, e.g. 2026.
    pub year: i64,
    /// Month, 1..=12.
    pub month: u32,
    /// Day of the month, 1..=31.
    pub day: u32,
    /// Hour, 0..=23.
    pub hour: u32,
    /// Minute, 0..=59.
    pub minute: u32,
    /// Second, 0..=59.
    pub second: u32,
    /// Microseconds, 0..=999_999.
    pub micros: u32,
    /// 0 = Sunday.
    pub weekday: u32,
}

impl Utc {
    /// Microseconds since 1970-01-01T00:00:00Z broken down.
    pub fn from_unix_us(t_us: u64) -> Self {
        let secs = (t_us / 1_000_000) as i64;
        let days = secs.div_euclid(86_400);
        let rem = secs.rem_euclid(86_400) as u32;
        let (year, month, day) = civil_from_days(days);
        Self {
            year,
            month,
            day,
            hour: rem / 3600,
            minute: rem / 60 % 60,
            second: rem % 60,
            micros: (t_us % 1_000_000) as u32,
            // 1970-01-01 was a Thursday (4).
            weekday: (days + 4).rem_euclid(7) as u32,
        }
    }

    /// Back to microseconds since the epoch; `None` for fields out of range or a date
    /// before 1970.
    pub fn to_unix_us(self) -> Option<u64> {
        if !(1..=12).contains(&self.month)
            || self.day == 0
            || self.day > days_in_month(self.year, self.month)
            || self.hour > 23
            || self.minute > 59
            || self.second > 60
            || self.micros > 999_999
        {
            return None;
        }
        let days = days_from_civil(self.year, self.month, self.day);
        let secs = days * 86_400
            + i64::from(self.hour) * 3600
            + i64::from(self.minute) * 60
            + i64::from(self.second);
        let secs = u64::try_from(secs).ok()?;
        secs.checked_mul(1_000_000)?
            .checked_add(u64::from(self.micros))
    }

    /// `Thu`.
    pub fn weekday_name(&self) -> &'static str {
        ["Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"][self.weekday as usize % 7]
    }

    /// `Nov`.
    pub fn month_name(&self) -> &'static str {
        [
            "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
        ][(self.month as usize + 11) % 12]
    }
}

/// `1436509052.249713` (or `12`, `0.5`) as microseconds, exactly: no floating point, so
/// every microsecond digit of a log survives. Digits beyond the sixth decimal are
/// truncated, fewer are padded. `None` if it is not digits with at most one point or
/// does not fit.
pub(crate) fn parse_seconds(text: &str) -> Option<u64> {
    let (secs, frac) = text.split_once('.').unwrap_or((text, ""));
    if secs.is_empty()
        || secs.len() > 20
        || !secs.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let secs: u64 = secs.parse().ok()?;
    let mut micros = 0u64;
    for b in frac.bytes().chain(std::iter::repeat(b'0')).take(6) {
        micros = micros * 10 + u64::from(b - b'0');
    }
    secs.checked_mul(1_000_000)?.checked_add(micros)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_round_trip() {
        for days in [
            -1, 0, 1, 59, 60, 365, 10_957, 11_016, 19_000, 20_415, 2_932_896,
        ] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days, "{y}-{m}-{d}");
        }
        let t = Utc::from_unix_us(1_436_509_052_249_713);
        assert_eq!(
            (t.year, t.month, t.day, t.hour, t.minute, t.second, t.micros),
            (2015, 7, 10, 6, 17, 32, 249_713)
        );
        assert_eq!(t.weekday_name(), "Fri");
        assert_eq!(t.month_name(), "Jul");
        assert_eq!(t.to_unix_us(), Some(1_436_509_052_249_713));
        let leap = Utc {
            month: 2,
            day: 29,
            year: 2023,
            ..t
        };
        assert_eq!(leap.to_unix_us(), None);
        assert!(Utc { year: 2024, ..leap }.to_unix_us().is_some());
        assert_eq!(Utc { year: 1969, ..t }.to_unix_us(), None);
    }

    #[test]
    fn seconds_are_exact() {
        assert_eq!(
            parse_seconds("1436509052.249713"),
            Some(1_436_509_052_249_713)
        );
        assert_eq!(parse_seconds("1.5"), Some(1_500_000));
        assert_eq!(parse_seconds("2"), Some(2_000_000));
        assert_eq!(parse_seconds("0.1234567"), Some(123_456));
        assert_eq!(parse_seconds("1."), Some(1_000_000));
        for bad in [
            "",
            ".5",
            "1.x",
            "-1.0",
            "+1",
            "1.2.3",
            "99999999999999999999.0",
        ] {
            assert_eq!(parse_seconds(bad), None, "{bad}");
        }
    }
}
