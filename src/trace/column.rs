//! The trace's columns, named once: the writer ([`super::format_row`])
//! writes a row's cells in this order, the header line ([`CSV_HEADER`]) is
//! generated from it, and a reader finds a cell by its column's index (a
//! file this build wrote) or, through [`Header`], by the column's name in
//! the file's own header (a file of another build, which may lack the last
//! columns).

/// The columns in order, each with its name in the header line; the enum,
/// its names and the header line are generated together.
macro_rules! columns {
    ($($(#[$m:meta])* $variant:ident = $name:literal),+ $(,)?) => {
        /// A column of `trace.csv` (what each holds: [`crate::trace`]).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Column {
            $($(#[$m])* $variant,)+
        }

        impl Column {
            /// Every column, in the file's order.
            pub const ALL: &'static [Column] = &[$(Column::$variant),+];

            /// The column's name in the header line.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Column::$variant => $name,)+
                }
            }
        }

        /// The CSV's header line: the columns' names, in order.
        pub const CSV_HEADER: &str = columns!(@join $($name),+);
    };
    (@join $first:literal $(, $rest:literal)*) => {
        concat!($first $(, ",", $rest)*)
    };
}

columns! {
    IngressIndex = "ingress_index",
    Sequence = "sequence",
    ConsoleIndex = "console_index",
    SendNs = "send_ns",
    IngressNs = "ingress_ns",
    Fate = "fate",
    Reason = "reason",
    Phase = "phase",
    Stage = "stage",
    DelayNs = "delay_ns",
    ReleaseSchedNs = "release_sched_ns",
    ReleaseNs = "release_ns",
    /// Left empty by the emulator; the runner fills it in.
    RecvNs = "recv_ns",
    Copy = "copy",
    CopiesDropped = "copies_dropped",
    Corrupted = "corrupted",
}

impl Column {
    /// How many columns a row has.
    pub const COUNT: usize = Column::ALL.len();

    /// The column's place in a row this build wrote (from 0).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The cell of this column among a row's `cells` (a row this build
    /// wrote), if the row has it.
    #[inline]
    pub fn of<'a>(self, cells: &[&'a str]) -> Option<&'a str> {
        cells.get(self.index()).copied()
    }
}

impl core::fmt::Display for Column {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Where each column stands in a file's header line, found by name: a
/// reader of a file that another build may have written (fewer columns, or
/// others beside them) looks its cells up here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    at: [Option<usize>; Column::COUNT],
}

impl Header {
    /// Reads a header line: names separated by commas (the line's end
    /// ignored).
    pub fn parse(line: &str) -> Header {
        let names: Vec<&str> = line.trim_end().split(',').collect();
        let mut at = [None; Column::COUNT];
        for c in Column::ALL {
            at[c.index()] = names.iter().position(|n| *n == c.name());
        }
        Header { at }
    }

    /// The position of column `c` in the file's rows, if its header names it.
    pub fn get(&self, c: Column) -> Option<usize> {
        self.at[c.index()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_is_the_names_in_order() {
        assert_eq!(
            CSV_HEADER,
            "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns,copy,copies_dropped,corrupted"
        );
        let names: Vec<&str> = CSV_HEADER.split(',').collect();
        assert_eq!(names.len(), Column::COUNT);
        for (k, c) in Column::ALL.iter().enumerate() {
            assert_eq!((c.index(), names[k]), (k, c.name()));
        }
        assert_eq!(Column::RecvNs.index(), 12);
    }

    #[test]
    fn a_header_finds_columns_by_name_wherever_they_stand() {
        let h = Header::parse(CSV_HEADER);
        assert!(Column::ALL.iter().all(|c| h.get(*c) == Some(c.index())));
        // An older file: fewer columns; another order.
        let h = Header::parse("fate,send_ns,ingress_index\r\n");
        assert_eq!((h.get(Column::Fate), h.get(Column::SendNs), h.get(Column::IngressIndex)), (Some(0), Some(1), Some(2)));
        assert_eq!(h.get(Column::Copy), None);
    }
}
