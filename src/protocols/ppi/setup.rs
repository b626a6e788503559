//! S7 "setup communication" (job function 0xF0): the first request an S7 master sends to
//! agree on how many jobs may be outstanding each way (max AmQ calling / called) and the
//! largest PDU. rackd's own PPI client does not send it (an S7-200 answers reads and writes
//! without it); the simulator answers it so that masters which do send it first
//! (libnodave's `_daveNegPDUlengthRequest`, python-snap7's `PPIClient.connect`) can connect.
//!
//! Parameters on the wire, after the 10-byte job header (12 in the ack-data reply):
//! `F0 00 CC CC DD DD PP PP`: function, reserved, max AmQ calling, max AmQ called, PDU
//! length, each big-endian.
//!
//! What the simulated S7-200 answers, where no Siemens document is public:
//! - **AmQ calling and called 1**: PPI carries one job at a time (the master polls each
//!   reply before it sends the next request), so the PLC grants at most 1 each way; a
//!   request for 0 is answered 0, as a server never grants more than asked.
//! - **PDU length at most 240**: the largest PDU an S7-200 offers; python-snap7's PPI client
//!   asks for exactly 240 (`PPIClient.pdu_length`), and a PPI SD2 frame cannot carry more
//!   than 246 PDU bytes anyway (length byte 255 minus DA, SA, FC; python-snap7 `ppi.py`).
//!   A smaller request is granted as asked.

/// The 0xF0 job function.
pub const SETUP: u8 = 0xF0;
/// Most jobs outstanding each way that a simulated S7-200 grants.
pub const MAX_AMQ: u16 = 1;
/// Largest PDU a simulated S7-200 grants.
pub const MAX_PDU: u16 = 240;

/// The parameters of a setup communication request or of its reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Setup {
    /// Most jobs the calling side may have outstanding.
    pub amq_calling: u16,
    /// Most jobs the called side may have outstanding.
    pub amq_called: u16,
    /// Largest PDU, in bytes.
    pub pdu_len: u16,
}

impl Setup {
    /// What an S7-200 grants for this request: each value clamped to its limit.
    pub fn negotiated(self) -> Setup {
        Setup {
            amq_calling: self.amq_calling.min(MAX_AMQ),
            amq_called: self.amq_called.min(MAX_AMQ),
            pdu_len: self.pdu_len.min(MAX_PDU),
        }
    }

    /// Appends the 8 parameter bytes.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&[SETUP, 0]);
        for v in [self.amq_calling, self.amq_called, self.pdu_len] {
            out.extend_from_slice(&v.to_be_bytes());
        }
    }

    /// Decodes the 8 parameter bytes; `None` if they are not a setup communication.
    pub fn decode(param: &[u8]) -> Option<Setup> {
        match param {
            [SETUP, _, c1, c0, d1, d0, p1, p0] => Some(Setup {
                amq_calling: u16::from_be_bytes([*c1, *c0]),
                amq_called: u16::from_be_bytes([*d1, *d0]),
                pdu_len: u16::from_be_bytes([*p1, *p0]),
            }),
            _ => None,
        }
    }
}
