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

mod frame;
mod link;
pub mod packet;
pub mod pcapng;
pub mod read;
mod recorder;
mod ring;

use std::io::{self, Write};

pub use frame::{Annotations, Direction, Frame, Verdict};
pub use link::{LINKTYPE_ETHERNET, LINKTYPE_UPPER_PDU, Link, SerialProtocol, Transport};
pub use read::{Capture, ReadError, read_file};
pub use recorder::{Limits, Recorder, Stats};

/// Writes `frames`, in order, as a pcapng file of one interface, `link`.
pub fn write(mut out: impl Write, link: &Link, frames: &[Frame]) -> io::Result<()> {
    out.write_all(&pcapng::section_header())?;
    out.write_all(&pcapng::interface(link.link_type(), &link.interface_name()))?;
    let mut wrapper = packet::Wrapper::new(link);
    for frame in frames {
        let data = wrapper.wrap(frame);
        out.write_all(&pcapng::packet(frame.time_us, &data, &frame.annotations.comment()))?;
    }
    out.flush()
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
}
