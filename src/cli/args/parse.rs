//! How flag values are parsed: numbers that must be finite (and above 0, or 0 or more), a
//! clip's up axis and its length unit; a bad value is one error line naming the flag.

/// How a number flag is checked while the command line is parsed: NaN and infinities are never
/// a setting, and rates, scales and learning rates must also be above 0.
#[derive(Clone, Copy)]
pub struct FiniteNumber<T> {
    above_zero: bool,
    kind: std::marker::PhantomData<T>,
}

/// A finite number above 0 (rates, tolerances, scales, learning rates, radii).
pub const fn positive<T>() -> FiniteNumber<T> {
    FiniteNumber {
        above_zero: true,
        kind: std::marker::PhantomData,
    }
}

/// A finite number of 0 or more (seconds, weights, ridges, margins, shares where 0 means "off").
pub const fn non_negative<T>() -> FiniteNumber<T> {
    FiniteNumber {
        above_zero: false,
        kind: std::marker::PhantomData,
    }
}

impl<T> clap::builder::TypedValueParser for FiniteNumber<T>
where
    T: std::str::FromStr + Into<f64> + Copy + Clone + Send + Sync + 'static,
{
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> std::result::Result<T, clap::Error> {
        let text = value.to_string_lossy();
        let parsed = text.trim().parse::<T>().ok().filter(|v| {
            let x: f64 = (*v).into();
            x.is_finite() && (x > 0.0 || (!self.above_zero && x == 0.0))
        });
        parsed.ok_or_else(|| {
            // The flag and the value first, as every other bad-input line names what was given.
            let flag = arg
                .and_then(|a| a.get_long())
                .map_or_else(|| "value".to_string(), |l| format!("--{l}"));
            let want = if self.above_zero {
                "a finite number above 0"
            } else {
                "a finite number, 0 or more"
            };
            clap::Error::raw(
                clap::error::ErrorKind::ValueValidation,
                format!("{flag} {text}: give {want}\n"),
            )
            .with_cmd(cmd)
        })
    }
}

pub fn parse_up(text: &str) -> Result<crate::rig::capture::UpAxis, String> {
    crate::rig::capture::UpAxis::parse(text)
        .ok_or_else(|| format!("'{text}': give x, y, z, -x, -y or -z"))
}

pub fn parse_units(text: &str) -> Result<crate::rig::capture::Units, String> {
    crate::rig::capture::Units::parse(text)
        .ok_or_else(|| format!("'{text}': give m, cm, mm, in, ft or cmu"))
}
