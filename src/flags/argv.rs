//! One argv renderer: each group of flags writes its own flags
//! ([`Render`]), and each process's arguments are their groups' flags and
//! their own, in the form that parses back to the same arguments.

use std::fmt::Display;

/// An argv under construction: flags with values, and switches.
#[derive(Debug, Default)]
pub struct Argv(Vec<String>);

impl Argv {
    /// `flag value`.
    pub fn val(&mut self, flag: &str, v: impl Display) -> &mut Self {
        self.0.extend([flag.to_string(), v.to_string()]);
        self
    }

    /// `flag value` when there is a value.
    pub fn opt(&mut self, flag: &str, v: Option<impl Display>) -> &mut Self {
        match v {
            Some(v) => self.val(flag, v),
            None => self,
        }
    }

    /// `flag value` unless the value is the flag's default.
    pub fn unless_default<T: Display + PartialEq>(&mut self, flag: &str, v: T, default: T) -> &mut Self {
        self.opt(flag, (v != default).then_some(v))
    }

    /// `flag` when on.
    pub fn switch(&mut self, flag: &str, on: bool) -> &mut Self {
        if on {
            self.0.push(flag.to_string());
        }
        self
    }

    /// The flags of a group.
    pub fn group(&mut self, g: &impl Render) -> &mut Self {
        g.render(self);
        self
    }

    /// Words as they are: a positional argument, or flags for another build.
    pub fn words(&mut self, words: impl IntoIterator<Item = String>) -> &mut Self {
        self.0.extend(words);
        self
    }

    /// The argv.
    pub fn finish(&mut self) -> Vec<String> {
        std::mem::take(&mut self.0)
    }
}

/// A group of flags, or a process's arguments, rendered as the flags that
/// parse back to it.
pub trait Render {
    /// Appends this group's flags to `argv`.
    fn render(&self, argv: &mut Argv);
}

/// The flags of `args` alone, as an argv.
pub fn render(args: &impl Render) -> Vec<String> {
    Argv::default().group(args).finish()
}
