//! Captures: a link's frames, as rackd sent and read them, written as a pcapng file that
//! Wireshark and tshark open. The flight recorder ([`Recorder`], one per device, fed by the
//! transport under every protocol client) keeps [`Frame`]s; [`write()`] turns them into
//! a file, and [`read_file`] reads one back ([`read`], for `rackd sim replay`). See
//! `docs/commissioning/capture.md` for opening one.
//!
//! # What a capture holds
//! One section, one interface (the [`Link`]), one packet per frame: the frame's bytes, its
//! time in microseconds, and a packet comment with rackd's [`Annotations`] (job, task,
//! retry, verdict, note). Nothing else goes in: no settings, no host names, no keys.
//!
//! # Decisions
//! - The pcapng writer is rackd's own ([`pcapng`], three block kinds and two option kinds,
//!   under 200 lines with tests). The maintained crate, `pcap-file`, writes blocks one
//!   builds oneself (its 2.0 is from 2022, 3.0 still a release candidate); the part that
//!   takes work, making Ethernet, IP, UDP and TCP headers around each frame ([`packet`]), is
//!   in no pcapng crate, and the writer stays on `std` and `bytes` alone (the recorder
//!   adds tokio's clock).
//! - IP links are written as Ethernet (link type 1) with made-up headers around the real
//!   addresses and ports, so Wireshark's own UDP/TCP analysis, its Modbus/TCP and Modbus/UDP
//!   dissectors and the `tcp.port`/`udp.port` Decode As rules work as on a real capture.
//! - Serial links are written as exported PDUs (link type 252, `exported_pdu`) naming the
//!   dissector (`mbrtu`, and the Lua dissectors' `mewtocol` and `s7ppi`), plus the
//!   direction. Tried with tshark 4.0.17 (Debian 12): a dissector a Lua script registers is
//!   found by this name, so no `user_dlts` table is needed and the file opens with no
//!   settings; it needs the Lua dissectors installed (`contrib/wireshark`).
//! - The direction decides the source: a sent frame goes from rackd's end (`local`) to the
//!   device's, a received one back.
//! - A recorder's capture is written part by part ([`write_from`], from a [`Reader`]): a
//!   part of the ring's records copied under the recorder's lock, decoded and written
//!   outside it, handed on (to a file, to an HTTP body) before the next is read; a capture
//!   of a full ring is never whole in memory.

mod frame;
mod link;
pub mod packet;
pub mod pcapng;
pub mod read;
pub mod reader;
mod recorder;
mod ring;

use std::io::{self, Write};

pub use frame::{Annotations, Direction, Frame, Verdict};
pub use link::{LINKTYPE_ETHERNET, LINKTYPE_UPPER_PDU, Link, SerialProtocol, Transport};
pub use read::{Capture, ReadError, read_file};
pub use reader::Reader;
pub use recorder::{Limits, Recorder, Stats};

/// A pcapng file being written: its header, then one packet per frame, each appended to
/// a buffer the caller hands on.
pub struct FileWriter {
    wrapper: packet::Wrapper,
}

impl FileWriter {
    /// A file of one interface, `link`: its header (section and interface) goes to `out`.
    pub fn start(link: &Link, out: &mut Vec<u8>) -> FileWriter {
        out.extend_from_slice(&pcapng::section_header());
        out.extend_from_slice(&pcapng::interface(link.link_type(), &link.interface_name()));
        FileWriter { wrapper: packet::Wrapper::new(link) }
    }

    /// Appends `frame`'s packet (frames in order: TCP sequence numbers run on).
    pub fn frame(&mut self, frame: &Frame, out: &mut Vec<u8>) {
        let data = self.wrapper.wrap(frame);
        out.extend_from_slice(&pcapng::packet(frame.time_us, &data, &frame.annotations.comment()));
    }
}

/// Writes `frames`, in order, as a pcapng file of one interface, `link`.
pub fn write(mut out: impl Write, link: &Link, frames: &[Frame]) -> io::Result<()> {
    let mut buf = Vec::new();
    let mut file = FileWriter::start(link, &mut buf);
    for frame in frames {
        file.frame(frame, &mut buf);
        if buf.len() >= reader::PART {
            out.write_all(&buf)?;
            buf.clear();
        }
    }
    out.write_all(&buf)?;
    out.flush()
}

/// Writes what `reader` reads as a pcapng file of one interface (the reader's link), part
/// by part: the packets of each part the reader reads ([`reader::PART`] bytes of records)
/// go to `out` in one buffer (the first with the file's header) before the next part is
/// read. The number of frames written.
pub fn write_from(reader: &mut Reader, mut out: impl FnMut(Vec<u8>) -> io::Result<()>) -> io::Result<usize> {
    let mut buf = Vec::new();
    let mut file = FileWriter::start(reader.link(), &mut buf);
    let mut written = 0;
    loop {
        let frames = reader.next(reader::PART);
        if frames.is_empty() {
            break;
        }
        for frame in &frames {
            file.frame(frame, &mut buf);
        }
        written += frames.len();
        out(std::mem::take(&mut buf))?;
    }
    if written == 0 {
        out(buf)?;
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_a_section_an_interface_and_a_packet_per_frame() {
        let link = Link::Serial { protocol: SerialProtocol::Mewtocol, port: "ttyS0".into() };
        let frames = [
            Frame::new(Direction::Sent, 10, b"%01#RCSX0000**\r".to_vec()),
            Frame::new(Direction::Received, 20, b"%01$RC120\r".to_vec())
                .with(Annotations { job: Some(3), ..Annotations::default() }),
        ];
        let mut out = Vec::new();
        write(&mut out, &link, &frames).unwrap();
        let mut blocks = Vec::new();
        let mut at = 0;
        while at < out.len() {
            let kind = u32::from_le_bytes(out[at..at + 4].try_into().unwrap());
            let len = u32::from_le_bytes(out[at + 4..at + 8].try_into().unwrap()) as usize;
            blocks.push(kind);
            at += len;
        }
        assert_eq!(at, out.len());
        assert_eq!(blocks, [pcapng::SHB, pcapng::IDB, pcapng::EPB, pcapng::EPB]);
        let text = String::from_utf8_lossy(&out);
        assert!(text.contains("job 3") && text.contains("ttyS0 mewtocol"), "{text}");
    }

    #[test]
    fn a_recorders_file_written_part_by_part_is_the_file_of_its_frames() {
        let link = Link::Ip {
            transport: Transport::Tcp,
            local: "127.0.0.1:4000".parse().unwrap(),
            remote: "127.0.0.1:502".parse().unwrap(),
        };
        let recorder = Recorder::new(link.clone(), Limits::default());
        for i in 0..3000u32 {
            let direction = if i % 2 == 0 { Direction::Sent } else { Direction::Received };
            recorder.record(
                direction,
                &[i as u8; 200],
                Annotations { job: Some(i.into()), ..Annotations::default() },
            );
        }
        let mut parts = Vec::new();
        let written = write_from(&mut recorder.reader(None), |part| {
            parts.push(part);
            Ok(())
        })
        .unwrap();
        assert_eq!(written, 3000);
        assert!(parts.len() > 2, "{} parts", parts.len());
        let mut whole = Vec::new();
        write(&mut whole, &link, &recorder.frames(None)).unwrap();
        assert_eq!(parts.concat(), whole);

        let empty = Recorder::new(link.clone(), Limits::default());
        let mut parts = Vec::new();
        write_from(&mut empty.reader(None), |part| {
            parts.push(part);
            Ok(())
        })
        .unwrap();
        assert_eq!(
            parts.concat(),
            [pcapng::section_header(), pcapng::interface(1, &link.interface_name())].concat()
        );
    }
}
