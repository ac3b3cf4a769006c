//! Named options: the closed sets of values a setting can take (the sweep order, the backup
//! path, the membership kind, the sample update, ...), each spelled **once**.
//!
//! An option is a plain `enum` declared with [`named_option!`](crate::named_option). The macro
//! gives it the one name per value that configuration files, the command line and Python use
//! ([`NamedOption::name`]), a help line per value, [`FromStr`](core::str::FromStr),
//! [`Display`](core::fmt::Display) and, with the `serde` feature, `Serialize`/`Deserialize`
//! through the same names. The command line builds its value parsers from
//! [`NamedOption::ALL`], so a value added here appears everywhere at once.
//!
//! ```
//! use fuzzyq_core::options::NamedOption;
//! use fuzzyq_core::Membership;
//!
//! assert_eq!("crisp".parse::<Membership>(), Ok(Membership::Crisp));
//! assert_eq!(Membership::Triangular.name(), "triangular");
//! assert_eq!(Membership::NAMES, ["triangular", "crisp"]);
//! let e = "round".parse::<Membership>().unwrap_err();
//! assert_eq!(e.to_string(), "unknown membership (expected one of: triangular, crisp)");
//! ```

use core::fmt;

/// A closed set of named values (see the [module docs](self)).
pub trait NamedOption: Copy + Eq + fmt::Debug + Sized + 'static {
    /// What the option sets, for messages (`"sweep"`, `"membership"`).
    const WHAT: &'static str;
    /// Every value, in declaration order.
    const ALL: &'static [Self];
    /// The names of [`ALL`](Self::ALL), in the same order.
    const NAMES: &'static [&'static str];

    /// The value's name in files, on the command line and in Python.
    fn name(self) -> &'static str;

    /// One line on what the value does.
    fn help(self) -> &'static str;

    /// The value named `name`, if any.
    #[must_use]
    fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|v| v.name() == name)
    }
}

/// A name that is not one of an option's values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnknownName {
    /// What the option sets.
    pub what: &'static str,
    /// The names it accepts.
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown {} (expected one of: ", self.what)?;
        for (i, n) in self.expected.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(n)?;
        }
        f.write_str(")")
    }
}

impl core::error::Error for UnknownName {}

/// Declares a [`NamedOption`] enum: every variant with its name and help line, once.
///
/// ```
/// fuzzyq_core::named_option! {
///     /// A switch.
///     #[derive(Default)]
///     pub enum Switch: "switch" {
///         /// Off.
///         #[default]
///         Off = "off" => "nothing happens",
///         /// On.
///         On = "on" => "something happens",
///     }
/// }
/// use fuzzyq_core::options::NamedOption;
/// assert_eq!(Switch::from_name("on"), Some(Switch::On));
/// assert_eq!(Switch::default().help(), "nothing happens");
/// ```
#[macro_export]
macro_rules! named_option {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident : $what:literal {
            $(
                $(#[$vmeta:meta])*
                $variant:ident = $vname:literal => $vhelp:literal
            ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        $vis enum $name {
            $(
                $(#[$vmeta])*
                $variant,
            )+
        }

        impl $crate::options::NamedOption for $name {
            const WHAT: &'static str = $what;
            const ALL: &'static [Self] = &[$(Self::$variant),+];
            const NAMES: &'static [&'static str] = &[$($vname),+];

            #[inline]
            fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $vname,)+
                }
            }

            fn help(self) -> &'static str {
                match self {
                    $(Self::$variant => $vhelp,)+
                }
            }
        }

        impl $name {
            /// The value's name in files, on the command line and in Python.
            #[inline]
            #[must_use]
            pub fn name(self) -> &'static str {
                <Self as $crate::options::NamedOption>::name(self)
            }
        }

        impl ::core::str::FromStr for $name {
            type Err = $crate::options::UnknownName;

            fn from_str(s: &str) -> ::core::result::Result<Self, Self::Err> {
                <Self as $crate::options::NamedOption>::from_name(s).ok_or(
                    $crate::options::UnknownName {
                        what: $what,
                        expected: <Self as $crate::options::NamedOption>::NAMES,
                    },
                )
            }
        }

        impl ::core::fmt::Display for $name {
            fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                f.write_str(self.name())
            }
        }

        $crate::__named_option_serde!($name);
    };
}

/// The serde half of [`named_option!`] (feature `serde`): values are their names.
#[cfg(feature = "serde")]
#[doc(hidden)]
#[macro_export]
macro_rules! __named_option_serde {
    ($name:ident) => {
        impl $crate::options::serde::Serialize for $name {
            fn serialize<S: $crate::options::serde::Serializer>(
                &self,
                s: S,
            ) -> ::core::result::Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }

        impl<'de> $crate::options::serde::Deserialize<'de> for $name {
            fn deserialize<D: $crate::options::serde::Deserializer<'de>>(
                d: D,
            ) -> ::core::result::Result<Self, D::Error> {
                // A name is read as a transient string (`visit_str`): a format reading from a
                // stream has no input to lend a `&'de str` from.
                d.deserialize_string($crate::options::NameVisitor::<Self>::new())
            }
        }
    };
}

/// Without the `serde` feature the serde half is empty.
#[cfg(not(feature = "serde"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __named_option_serde {
    ($name:ident) => {};
}

#[cfg(feature = "serde")]
#[doc(hidden)]
pub use serde;

/// Reads a [`NamedOption`] from a string (feature `serde`).
#[cfg(feature = "serde")]
#[doc(hidden)]
pub struct NameVisitor<T>(core::marker::PhantomData<T>);

#[cfg(feature = "serde")]
impl<T> NameVisitor<T> {
    /// A visitor.
    #[must_use]
    pub const fn new() -> Self {
        Self(core::marker::PhantomData)
    }
}

#[cfg(feature = "serde")]
impl<T> Default for NameVisitor<T> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(feature = "serde")]
impl<T: NamedOption> serde::de::Visitor<'_> for NameVisitor<T> {
    type Value = T;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a {} name", T::WHAT)
    }

    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<T, E> {
        T::from_name(v).ok_or_else(|| E::unknown_variant(v, T::NAMES))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    crate::named_option! {
        /// A test option.
        pub enum Mode: "mode" {
            /// A.
            Alpha = "alpha" => "the first",
            /// B.
            Beta = "beta-two" => "the second",
        }
    }

    #[test]
    fn names_parse_display_and_refuse_unknown_values() {
        assert_eq!(Mode::ALL, [Mode::Alpha, Mode::Beta]);
        assert_eq!(Mode::NAMES, ["alpha", "beta-two"]);
        for &m in Mode::ALL {
            assert_eq!(m.name().parse::<Mode>(), Ok(m));
            assert_eq!(std::format!("{m}"), m.name());
        }
        assert_eq!(Mode::Beta.help(), "the second");
        let e = "gamma".parse::<Mode>().unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "unknown mode (expected one of: alpha, beta-two)"
        );
    }
}
