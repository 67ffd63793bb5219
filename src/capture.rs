//! Reader for recorded ITP captures (SPEC §7).
// placeholder until the capture reader lands
pub struct Record { pub time_ns: u64 }
pub struct Capture { pub records: Vec<Record> }
pub fn load(_p: &std::path::Path) -> Result<Capture, std::io::Error> { unimplemented!() }
