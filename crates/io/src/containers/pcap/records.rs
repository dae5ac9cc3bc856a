//! A capture's records, classic pcap or pcapng, as (time, link type, frame).
//!
//! Classic pcap: a 24-byte header (magic, version, snap length, link type), then
//! records of {seconds, microseconds or nanoseconds, captured length, original
//! length} and the frame. pcapng: blocks of {type, length, body, length}: a section
//! header (its byte order), interface descriptions (link type, time resolution) and
//! enhanced packet blocks (interface, 64-bit time, captured length, frame).

/// How a capture's frames begin (its link type).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Link {
    Ethernet,
    /// Linux "cooked" capture (tcpdump -i any).
    LinuxSll,
    /// IPv4 packets with no link header.
    Ipv4,
}

impl Link {
    fn of(link_type: u32) -> Option<Self> {
        match link_type & 0x0FFF_FFFF {
            1 => Some(Link::Ethernet),
            113 => Some(Link::LinuxSll),
            101 | 228 => Some(Link::Ipv4),
            _ => None,
        }
    }
}

/// Which of the two formats, and what its header says.
#[derive(Clone, Copy, Debug)]
pub(super) enum Capture {
    Classic { headers: ClassicHeaders, link: Link },
    Ng,
}

const CLASSIC_HEADER: usize = 24;
/// The largest snap length a capture tool writes (tcpdump's default, 256 KiB).
const MAX_SNAP_LENGTH: usize = 262_144;
const RECORD_HEADER: usize = 16;
const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;

/// A stretch of a capture whose records (pcapng: blocks) are damaged: reading goes
/// on at `resume`, the next place where they read right again (the end when none:
/// `to_end`).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Damaged {
    pub start: usize,
    pub resume: usize,
    pub to_end: bool,
    /// The capture times of the packets either side, ns (0 before the first; the
    /// one after, when known).
    pub after_ns: u64,
    pub before_ns: Option<u64>,
}

/// What `read` found in a capture.
#[derive(Debug)]
pub(super) struct Layout {
    pub capture: Capture,
    /// Where its last whole record ends.
    pub end: usize,
    /// Where a cut last record begins.
    pub cut: Option<usize>,
    /// Damaged stretches, in order.
    pub damaged: Vec<Damaged>,
}

/// Two records in a row further apart in time than this are not where reading
/// resumes past damage (a clock may jump between them, but not at that place too).
const MAX_RECORD_GAP_NS: u64 = 86_400_000_000_000;
/// The least frame a record where reading resumes may hold: an IPv4 header (a run of
/// zeros in packet data reads as empty records).
const MIN_RESUMING_FRAME: usize = 20;

/// How a classic capture's record headers read.
#[derive(Clone, Copy, Debug)]
pub(super) struct ClassicHeaders {
    big_endian: bool,
    nanoseconds: bool,
    snap_length: usize,
}

impl ClassicHeaders {
    /// The time (ns) and captured length of the record at `at`, when its header is
    /// one a writer gives: lengths within the snap length and the packet's own, a
    /// fraction of a second below one.
    fn record(&self, bytes: &[u8], at: usize) -> Option<(u64, usize)> {
        let header = bytes.get(at..at + RECORD_HEADER)?;
        let field = |k: usize| read_u32(header, 4 * k, self.big_endian) as usize;
        let (seconds, fraction, captured, original) = (field(0), field(1), field(2), field(3));
        let (unit, per_second) = match self.nanoseconds {
            true => (1, 1_000_000_000),
            false => (1_000, 1_000_000),
        };
        let stamp_ns = seconds as u64 * 1_000_000_000 + fraction as u64 * unit;
        let lengths = captured <= self.snap_length
            && captured <= original
            && original <= MAX_SNAP_LENGTH.max(self.snap_length);
        (lengths && fraction < per_second).then_some((stamp_ns, captured))
    }

    /// The first place after `from` where two records in a row, each holding a
    /// frame, less than a day apart (or one that ends the capture) read right:
    /// where reading resumes past damage.
    fn resume_after(&self, bytes: &[u8], from: usize) -> Option<usize> {
        let framed = |at: usize| {
            self.record(bytes, at)
                .filter(|&(_, captured)| captured >= MIN_RESUMING_FRAME)
        };
        (from + 1..bytes.len().saturating_sub(RECORD_HEADER - 1)).find(|&at| {
            let Some((stamp_ns, captured)) = framed(at) else {
                return false;
            };
            let next = at + RECORD_HEADER + captured;
            next == bytes.len()
                || framed(next)
                    .is_some_and(|(next_ns, _)| next_ns.abs_diff(stamp_ns) <= MAX_RECORD_GAP_NS)
        })
    }
}

/// The capture `bytes` holds: its format, where its last whole record ends, a cut
/// last record, and (classic captures) the damaged stretches reading steps over.
pub(super) fn read(bytes: &[u8]) -> Result<Layout, String> {
    let magic = bytes.get(..4).ok_or("shorter than a pcap header")?;
    let (big_endian, nanoseconds) = match magic {
        [0xd4, 0xc3, 0xb2, 0xa1] => (false, false),
        [0xa1, 0xb2, 0xc3, 0xd4] => (true, false),
        [0x4d, 0x3c, 0xb2, 0xa1] => (false, true),
        [0xa1, 0xb2, 0x3c, 0x4d] => (true, true),
        [0x0a, 0x0d, 0x0d, 0x0a] => {
            let (end, cut, damaged) = whole_blocks(bytes)?;
            return Ok(Layout {
                capture: Capture::Ng,
                end,
                cut,
                damaged,
            });
        }
        _ => return Err("not a pcap capture".into()),
    };
    if bytes.len() < CLASSIC_HEADER {
        return Err("shorter than a pcap header".into());
    }
    let link_type = read_u32(bytes, 20, big_endian);
    let link = Link::of(link_type).ok_or_else(|| {
        format!("link type {link_type}: travmap reads Ethernet, Linux cooked and raw IPv4 captures")
    })?;
    // No record holds more than the capture's snap length (writers set 65535 or
    // 262144; 0 in some, meaning no limit but the largest link frame).
    let snap_length = match read_u32(bytes, 16, big_endian) as usize {
        0 => MAX_SNAP_LENGTH,
        length => length.max(u16::MAX as usize),
    };
    let headers = ClassicHeaders {
        big_endian,
        nanoseconds,
        snap_length,
    };
    let (mut at, mut last_ns, mut damaged) = (CLASSIC_HEADER, None, Vec::new());
    while at + RECORD_HEADER <= bytes.len() {
        // A header no writer gives is damage, not the end of a cut capture: the
        // records after it are read from where they read right again.
        let Some((stamp_ns, captured)) = headers.record(bytes, at) else {
            let resume = headers.resume_after(bytes, at);
            damaged.push(Damaged {
                start: at,
                resume: resume.unwrap_or(bytes.len()),
                to_end: resume.is_none(),
                after_ns: last_ns.unwrap_or(0),
                before_ns: resume
                    .and_then(|r| headers.record(bytes, r))
                    .map(|(ns, _)| ns),
            });
            at = resume.unwrap_or(bytes.len());
            continue;
        };
        let next = at + RECORD_HEADER + captured;
        if next > bytes.len() {
            break;
        }
        (at, last_ns) = (next, Some(stamp_ns));
    }
    let cut = (at < bytes.len()).then_some(at);
    Ok(Layout {
        capture: Capture::Classic { headers, link },
        end: at,
        cut,
        damaged,
    })
}

/// The pcapng block types reading resumes at past damage: a section header, an
/// interface description, a simple and an enhanced packet, interface statistics.
const NG_BLOCK_TYPES: [u32; 5] = [0x0A0D_0D0A, 1, 3, 6, 5];

/// Whether a whole pcapng block begins at `at` (of a type of [`NG_BLOCK_TYPES`] when
/// `known` says so; other writers' blocks are read past): a length of at least 12,
/// a multiple of 4, inside the file, repeated at its end.
fn ng_block_at(bytes: &[u8], at: usize, big_endian: bool, known: bool) -> bool {
    let Some(header) = bytes.get(at..at + 8) else {
        return false;
    };
    let length = read_u32(header, 4, big_endian) as usize;
    (!known || NG_BLOCK_TYPES.contains(&read_u32(header, 0, big_endian)))
        && length >= 12
        && length.is_multiple_of(4)
        && at
            .checked_add(length)
            .filter(|&end| end <= bytes.len())
            .is_some_and(|end| read_u32(bytes, end - 4, big_endian) as usize == length)
}

/// A pcapng capture's whole blocks: where they end, where a cut one begins, and the
/// damaged stretches (a block whose length is not repeated at its end, or is no
/// block's) with where whole blocks begin again (blocks lie on 4-byte bounds).
fn whole_blocks(bytes: &[u8]) -> Result<(usize, Option<usize>, Vec<Damaged>), String> {
    let mut at = 0;
    let mut big_endian = false;
    let mut damaged = Vec::new();
    while at + 12 <= bytes.len() {
        if bytes[at..at + 4] == [0x0a, 0x0d, 0x0d, 0x0a] {
            big_endian = match read_u32(bytes, at + 8, false) {
                BYTE_ORDER_MAGIC => false,
                magic if magic.swap_bytes() == BYTE_ORDER_MAGIC => true,
                _ => return Err(format!("a pcapng section at byte {at} of no byte order")),
            };
        }
        if ng_block_at(bytes, at, big_endian, false) {
            at += read_u32(bytes, at + 4, big_endian) as usize;
            continue;
        }
        let resume = (at + 4..bytes.len())
            .step_by(4)
            .find(|&next| ng_block_at(bytes, next, big_endian, true));
        let length = read_u32(bytes, at + 4, big_endian) as usize;
        // A well-formed length past the end with no whole block after it: the
        // capture was cut inside its last block.
        if resume.is_none() && length >= 12 && length.is_multiple_of(4) && at + length > bytes.len()
        {
            break;
        }
        damaged.push(Damaged {
            start: at,
            resume: resume.unwrap_or(bytes.len()),
            to_end: resume.is_none(),
            after_ns: 0,
            before_ns: None,
        });
        at = resume.unwrap_or(bytes.len());
    }
    Ok((at, (at < bytes.len()).then_some(at), damaged))
}

/// One record of a capture, or a damaged stretch stepped over.
pub(super) type Record<'a> = Result<(usize, u64, Link, &'a [u8]), Damaged>;

/// The records of a capture `read` laid out, up to its end: (byte offset, time in
/// ns, link, frame), each damaged stretch where it lies. Frames of a link type
/// travmap does not read are left out.
pub(super) fn records<'a>(
    bytes: &'a [u8],
    layout: &Layout,
) -> Box<dyn Iterator<Item = Record<'a>> + 'a> {
    let bytes = &bytes[..layout.end];
    match layout.capture {
        Capture::Classic { headers, link } => {
            let mut at = CLASSIC_HEADER;
            let mut damaged = layout.damaged.clone().into_iter().peekable();
            Box::new(std::iter::from_fn(move || {
                if let Some(stretch) = damaged.next_if(|d| d.start == at) {
                    at = stretch.resume;
                    return Some(Err(stretch));
                }
                // `read` walked these records: each header reads right.
                let (stamp_ns, captured) = headers.record(bytes, at)?;
                let frame = &bytes[at + RECORD_HEADER..at + RECORD_HEADER + captured];
                let offset = at;
                at += RECORD_HEADER + captured;
                Some(Ok((offset, stamp_ns, link, frame)))
            }))
        }
        Capture::Ng => Box::new(ng_records(bytes, layout.damaged.clone())),
    }
}

/// An interface of a pcapng section: its link, and its time unit.
struct Interface {
    link: Option<Link>,
    resolution: Resolution,
}

/// A pcapng interface's time unit (`if_tsresol`).
#[derive(Clone, Copy)]
enum Resolution {
    /// 10^-n seconds.
    Decimal(u8),
    /// 2^-n seconds.
    Binary(u8),
}

impl Resolution {
    fn nanoseconds(self, ticks: u64) -> u64 {
        let ticks = u128::from(ticks);
        let ns = match self {
            Resolution::Decimal(n) if n <= 9 => ticks * 10u128.pow(9 - u32::from(n)),
            Resolution::Decimal(n) => ticks / 10u128.pow(u32::from(n.min(38)) - 9),
            Resolution::Binary(n) => (ticks * 1_000_000_000) >> n.min(127),
        };
        ns.min(u128::from(u64::MAX)) as u64
    }
}

/// A pcapng capture's packets, each damaged stretch where it lies (stamped with the
/// last packet's time before it).
fn ng_records(bytes: &[u8], damaged: Vec<Damaged>) -> impl Iterator<Item = Record<'_>> {
    let mut at = 0;
    let mut big_endian = false;
    let mut interfaces: Vec<Interface> = Vec::new();
    let mut damaged = damaged.into_iter().peekable();
    let mut last_ns = 0;
    std::iter::from_fn(move || {
        while at + 12 <= bytes.len() {
            if let Some(mut stretch) = damaged.next_if(|d| d.start == at) {
                at = stretch.resume;
                stretch.after_ns = last_ns;
                return Some(Err(stretch));
            }
            let block_type = read_u32(bytes, at, big_endian);
            if block_type == 0x0A0D_0D0A {
                big_endian = read_u32(bytes, at + 8, false) != BYTE_ORDER_MAGIC;
                interfaces.clear();
            }
            let length = read_u32(bytes, at + 4, big_endian) as usize;
            let body = &bytes[at + 8..at + length - 4];
            let offset = at;
            at += length;
            match block_type {
                1 if body.len() >= 8 => interfaces.push(Interface {
                    link: Link::of(u32::from(read_u16(body, 0, big_endian))),
                    resolution: resolution(&body[8..], big_endian),
                }),
                6 if body.len() >= 20 => {
                    let interface = interfaces.get(read_u32(body, 0, big_endian) as usize);
                    let ticks = u64::from(read_u32(body, 4, big_endian)) << 32
                        | u64::from(read_u32(body, 8, big_endian));
                    let captured = read_u32(body, 12, big_endian) as usize;
                    let (Some(interface), Some(frame)) = (interface, body.get(20..20 + captured))
                    else {
                        continue;
                    };
                    if let Some(link) = interface.link {
                        let stamp_ns = interface.resolution.nanoseconds(ticks);
                        last_ns = stamp_ns;
                        return Some(Ok((offset, stamp_ns, link, frame)));
                    }
                }
                _ => {}
            }
        }
        None
    })
}

/// An interface description's `if_tsresol` option (code 9), else microseconds.
fn resolution(mut options: &[u8], big_endian: bool) -> Resolution {
    while options.len() >= 4 {
        let (code, length) = (
            read_u16(options, 0, big_endian),
            usize::from(read_u16(options, 2, big_endian)),
        );
        if code == 0 {
            break;
        }
        if code == 9
            && length == 1
            && let Some(&value) = options.get(4)
        {
            return match value & 0x80 {
                0 => Resolution::Decimal(value),
                _ => Resolution::Binary(value & 0x7F),
            };
        }
        options = options
            .get(4 + length.next_multiple_of(4)..)
            .unwrap_or_default();
    }
    Resolution::Decimal(6)
}

fn read_u16(bytes: &[u8], at: usize, big_endian: bool) -> u16 {
    let word = [bytes[at], bytes[at + 1]];
    match big_endian {
        true => u16::from_be_bytes(word),
        false => u16::from_le_bytes(word),
    }
}

pub(super) fn read_u32(bytes: &[u8], at: usize, big_endian: bool) -> u32 {
    let word = [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
    match big_endian {
        true => u32::from_be_bytes(word),
        false => u32::from_le_bytes(word),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pcapng block of `block_type` around `body`, little-endian.
    fn block(block_type: u32, body: &[u8]) -> Vec<u8> {
        let length = (12 + body.len().next_multiple_of(4)) as u32;
        let mut out = block_type.to_le_bytes().to_vec();
        out.extend(length.to_le_bytes());
        out.extend(body);
        out.resize(length as usize - 4, 0);
        out.extend(length.to_le_bytes());
        out
    }

    fn enhanced_packet(interface: u32, ticks: u64, frame: &[u8]) -> Vec<u8> {
        let mut body = interface.to_le_bytes().to_vec();
        body.extend(((ticks >> 32) as u32).to_le_bytes());
        body.extend((ticks as u32).to_le_bytes());
        body.extend((frame.len() as u32).to_le_bytes());
        body.extend((frame.len() as u32).to_le_bytes());
        body.extend(frame);
        block(6, &body)
    }

    /// A little-endian pcapng section header block, version 1.0, of unknown length.
    fn section_header() -> Vec<u8> {
        let mut section = BYTE_ORDER_MAGIC.to_le_bytes().to_vec();
        section.extend([1, 0, 0, 0]);
        section.extend(u64::MAX.to_le_bytes());
        block(0x0A0D_0D0A, &section)
    }

    #[test]
    fn a_damaged_pcapng_block_is_stepped_over_to_the_next_whole_block() {
        let mut whole = section_header();
        whole.extend(block(1, &[1, 0, 0, 0, 0, 0, 4, 0]));
        let at = |k: usize| whole.len() + k * enhanced_packet(0, 0, b"packet").len();
        let (second, third) = (at(1), at(2));
        for k in 0..3 {
            whole.extend(enhanced_packet(0, 1_000_000 * (k + 1), b"packet"));
        }
        // A whole block of a type travmap does not know (name resolution) is no damage.
        let mut with_names = whole.clone();
        with_names.extend(block(4, b"names"));
        let layout = read(&with_names).unwrap();
        assert!(layout.damaged.is_empty() && layout.end == with_names.len());
        // The second block's length: not repeated at its end, not a multiple of 4,
        // or past the end of the file (a third block follows: damage, not a cut).
        for length in [44u32, 45, 1 << 30] {
            let mut bytes = whole.clone();
            bytes[second + 4..second + 8].copy_from_slice(&length.to_le_bytes());
            let layout = read(&bytes).unwrap();
            assert_eq!((layout.end, layout.cut), (bytes.len(), None), "{length}");
            let read: Vec<_> = records(&bytes, &layout).collect();
            let stamps: Vec<u64> = read.iter().flatten().map(|r| r.1).collect();
            assert_eq!(stamps, [1_000_000_000, 3_000_000_000], "{length}");
            let stretch = read.iter().find_map(|r| r.as_ref().err()).unwrap();
            let expected = (second, third, false, 1_000_000_000);
            assert_eq!(
                (
                    stretch.start,
                    stretch.resume,
                    stretch.to_end,
                    stretch.after_ns
                ),
                expected
            );
        }
    }

    #[test]
    fn pcapng_packets_keep_their_interfaces_link_and_time_unit() {
        let mut capture = section_header();
        // Interface 0: Ethernet in microseconds; 1: raw IPv4 in nanoseconds (an
        // if_tsresol option); 2: a link type travmap does not read.
        capture.extend(block(1, &[1, 0, 0, 0, 0, 0, 4, 0]));
        let nanoseconds = [228, 0, 0, 0, 0, 0, 4, 0, 9, 0, 1, 0, 9, 0, 0, 0, 0, 0, 0, 0];
        capture.extend(block(1, &nanoseconds));
        capture.extend(block(1, &[105, 0, 0, 0, 0, 0, 4, 0]));
        let first_at = capture.len();
        capture.extend(enhanced_packet(0, 1_500_000, b"first"));
        capture.extend(block(5, b"statistics"));
        let second_at = capture.len();
        capture.extend(enhanced_packet(1, 2_000_000_007, b"second"));
        capture.extend(enhanced_packet(2, 3, b"wifi"));
        // A record cut short is not read.
        let whole = capture.len();
        capture.extend(&enhanced_packet(0, 9, b"cut")[..20]);
        let layout = read(&capture).unwrap();
        assert!(matches!(layout.capture, Capture::Ng));
        assert_eq!((layout.end, layout.cut), (whole, Some(whole)));
        let read: Vec<_> = records(&capture, &layout).collect();
        assert_eq!(
            read,
            [
                Ok((first_at, 1_500_000_000, Link::Ethernet, &b"first"[..])),
                Ok((second_at, 2_000_000_007, Link::Ipv4, &b"second"[..])),
            ]
        );
    }

    #[test]
    fn time_units_of_every_resolution_are_nanoseconds() {
        assert_eq!(Resolution::Decimal(6).nanoseconds(3), 3_000);
        assert_eq!(Resolution::Decimal(9).nanoseconds(3), 3);
        assert_eq!(Resolution::Decimal(12).nanoseconds(3_000), 3);
        assert_eq!(Resolution::Binary(10).nanoseconds(1024), 1_000_000_000);
        assert_eq!(Resolution::Decimal(0).nanoseconds(u64::MAX), u64::MAX);
    }
}
