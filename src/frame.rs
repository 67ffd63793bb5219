//! ITP master-to-slave frame codec (SPEC §2).
