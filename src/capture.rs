//! Reader for recorded ITP captures (SPEC §7).
