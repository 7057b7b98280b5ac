use std::fmt;
use std::str::FromStr;

/// Physical units robotid tables carry in their field metadata (`unit` key).
/// The symbols are plain ASCII so every Parquet reader shows them as-is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Unit {
    Second,
    Hertz,
    Radian,
    RadianPerSecond,
    RadianPerSecond2,
    NewtonMetre,
    Ampere,
    Count,
    Radian2,
    NewtonMetre2,
    Ampere2,
    Dimensionless,
    Percent,
}

impl Unit {
    pub const ALL: [Unit; 13] = [
        Unit::Second,
        Unit::Hertz,
        Unit::Radian,
        Unit::RadianPerSecond,
        Unit::RadianPerSecond2,
        Unit::NewtonMetre,
        Unit::Ampere,
        Unit::Count,
        Unit::Radian2,
        Unit::NewtonMetre2,
        Unit::Ampere2,
        Unit::Dimensionless,
        Unit::Percent,
    ];

    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Second => "s",
            Unit::Hertz => "Hz",
            Unit::Radian => "rad",
            Unit::RadianPerSecond => "rad/s",
            Unit::RadianPerSecond2 => "rad/s^2",
            Unit::NewtonMetre => "N*m",
            Unit::Ampere => "A",
            Unit::Count => "count",
            Unit::Radian2 => "rad^2",
            Unit::NewtonMetre2 => "N^2*m^2",
            Unit::Ampere2 => "A^2",
            Unit::Dimensionless => "1",
            Unit::Percent => "%",
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// A unit symbol robotid does not know.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownUnit(pub String);

impl fmt::Display for UnknownUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown unit `{}`", self.0)
    }
}

impl std::error::Error for UnknownUnit {}

impl FromStr for Unit {
    type Err = UnknownUnit;
    /// Accepts the canonical symbol and common spellings (`Nm`, `N·m`, `rad/s2`).
    fn from_str(s: &str) -> Result<Self, UnknownUnit> {
        let t = s.trim();
        let u = match t {
            "s" | "sec" | "second" | "seconds" => Unit::Second,
            "Hz" | "hz" => Unit::Hertz,
            "rad" | "radian" | "radians" => Unit::Radian,
            "rad/s" => Unit::RadianPerSecond,
            "rad/s^2" | "rad/s2" | "rad/s²" => Unit::RadianPerSecond2,
            "N*m" | "Nm" | "N.m" | "N·m" | "N m" => Unit::NewtonMetre,
            "A" | "amp" | "ampere" => Unit::Ampere,
            "count" | "counts" | "cnt" => Unit::Count,
            "rad^2" | "rad2" | "rad²" => Unit::Radian2,
            "N^2*m^2" | "N2m2" | "(N*m)^2" | "N²m²" => Unit::NewtonMetre2,
            "A^2" | "A2" | "A²" => Unit::Ampere2,
            "1" | "" => Unit::Dimensionless,
            "%" | "percent" => Unit::Percent,
            _ => return Err(UnknownUnit(t.to_string())),
        };
        Ok(u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symbols_round_trip() {
        for u in Unit::ALL {
            assert_eq!(u.symbol().parse::<Unit>(), Ok(u));
        }
        assert_eq!("Nm".parse::<Unit>(), Ok(Unit::NewtonMetre));
        assert!("furlong".parse::<Unit>().is_err());
    }
}
