//! `rackd plc` requests beyond reading and writing consecutive memory, for commissioning:
//! MC random reads (0403) and multi-block reads (0406), Modbus Read FIFO Queue (24) and
//! Diagnostics (8), and Modbus reads of any count (`read --unchecked`). Each answers `NAME VALUE` lines like `read`, or with `--json` the same JSON array
//! of `{"address", "value"}` (values as text).

use anyhow::{Context, anyhow, bail};

use super::capture::Capture;
use super::hints;
use crate::protocols::link::{self, LinkConfig, LinkError};
use crate::protocols::modbus::address::Table;
use crate::protocols::modbus::{Request, Response};
use crate::protocols::protocol::Family;
use crate::protocols::{PlcError, PlcMemory, mc3e, modbus};

/// The request, as the command line names it.
#[derive(Debug)]
pub enum Extra<'a> {
    /// MC random read: words at `words`, double words at `dwords`.
    Random {
        /// Word addresses.
        words: &'a [String],
        /// Double-word addresses.
        dwords: &'a [String],
    },
    /// MC multi-block read: `ADDRESS:COUNT` each.
    Blocks(&'a [String]),
    /// Modbus Read FIFO Queue at the pointer register.
    Fifo(&'a str),
    /// Modbus Diagnostics sub-function, in hexadecimal as the specification writes it.
    Diagnostics(&'a str),
    /// A Modbus read of any count (0, past 125 words or 2000 bits), to test a device's limits.
    Unchecked {
        /// The first address.
        address: &'a str,
        /// How many items, sent as asked.
        count: u16,
    },
}

/// Runs the request and returns `(name, value)` pairs in order.
/// With `capture`, the link's recorder is handed to it.
pub async fn run(
    link: &LinkConfig,
    extra: Extra<'_>,
    capture: Option<&Capture>,
) -> anyhow::Result<Vec<(String, String)>> {
    let protocol = link.protocol;
    let device = |e: PlcError| anyhow!(hints::explain(&e, protocol));
    let setup = |e: LinkError| match e {
        LinkError::Plc(e) => anyhow!(hints::explain(&e, protocol)),
        other => anyhow!(other),
    };
    match extra {
        Extra::Random { words, dwords } => {
            let client = mc_only(link, capture).map_err(setup)?;
            let w = parse_all(words, mc3e::address::parse_address).map_err(device)?;
            let d = parse_all(dwords, mc3e::address::parse_address).map_err(device)?;
            let (wv, dv) = client.read_random(&w, &d).await.map_err(device).context("random read (0403)")?;
            let mut out: Vec<(String, String)> =
                w.iter().zip(wv).map(|(a, v)| (mc3e::address::format_address(a), v.to_string())).collect();
            out.extend(d.iter().zip(dv).map(|(a, v)| (mc3e::address::format_address(a), v.to_string())));
            Ok(out)
        }
        Extra::Blocks(specs) => {
            let client = mc_only(link, capture).map_err(setup)?;
            let mut blocks = Vec::with_capacity(specs.len());
            for spec in specs {
                let (at, count) = spec
                    .split_once(':')
                    .with_context(|| format!("block {spec:?}: write ADDRESS:COUNT, e.g. D100:10"))?;
                let count: u16 = count.parse().with_context(|| format!("block {spec:?}: bad count"))?;
                blocks.push((mc3e::address::parse_address(at).map_err(device)?, count));
            }
            let values = client.read_blocks(&blocks).await.map_err(device).context("block read (0406)")?;
            let mut out = Vec::new();
            for ((start, _), words) in blocks.iter().zip(values) {
                for (i, v) in words.into_iter().enumerate() {
                    out.push((block_label(start, i as u32), v.to_string()));
                }
            }
            Ok(out)
        }
        Extra::Fifo(at) => {
            let client = modbus_only(link, capture).await.map_err(setup)?;
            let address = modbus::address::parse(at).map_err(device)?;
            let pointer = u16::try_from(address.index).context("FIFO pointer address past 65535")?;
            let words =
                client.read_fifo_queue(pointer).await.map_err(device).context("read FIFO queue (24)")?;
            let mut out = vec![("count".to_owned(), words.len().to_string())];
            out.extend(words.iter().enumerate().map(|(i, w)| (format!("fifo[{i}]"), w.to_string())));
            Ok(out)
        }
        Extra::Diagnostics(sub) => {
            let client = modbus_only(link, capture).await.map_err(setup)?;
            let code = u16::from_str_radix(sub.trim_start_matches("0x"), 16)
                .with_context(|| format!("sub-function {sub:?}: four hex digits, e.g. 000B"))?;
            let value = client.diagnostic(code).await.map_err(device).context("diagnostics (8)")?;
            Ok(vec![(format!("{code:04X}"), value.to_string())])
        }
        Extra::Unchecked { address, count } => {
            let client = modbus_only(link, capture).await.map_err(setup)?;
            let start = modbus::address::parse(address).map_err(device)?;
            let at = u16::try_from(start.index).context("address past 65535")?;
            let request = match Table::from_area(&start.area) {
                Some(Table::Coils) => Request::ReadCoils { address: at, count },
                Some(Table::DiscreteInputs) => Request::ReadDiscreteInputs { address: at, count },
                Some(Table::InputRegisters) => Request::ReadInputRegisters { address: at, count },
                _ => Request::ReadHoldingRegisters { address: at, count },
            };
            let reply = client.call_unchecked(&request).await.map_err(device).context("unchecked read")?;
            let values: Vec<u16> = match reply {
                Response::ReadCoils(b) | Response::ReadDiscreteInputs(b) => {
                    b.into_iter().map(u16::from).collect()
                }
                Response::ReadHoldingRegisters(w) | Response::ReadInputRegisters(w) => w,
                _ => bail!("the device answered another function"),
            };
            Ok(values
                .into_iter()
                .enumerate()
                .map(|(i, v)| (modbus::address::format(&start.offset(i as u32)), v.to_string()))
                .collect())
        }
    }
}

/// The `i`th word of a block (a bit device's block is read as `K4` words: `K4M100`, `K4M116`).
fn block_label(start: &crate::protocols::Address, i: u32) -> String {
    mc3e::address::format_address(&start.offset(i * mc3e::address::step(start)))
}

fn parse_all(
    texts: &[String],
    parse: fn(&str) -> Result<crate::protocols::Address, PlcError>,
) -> Result<Vec<crate::protocols::Address>, PlcError> {
    texts.iter().map(|t| parse(t)).collect()
}

fn mc_only(link: &LinkConfig, capture: Option<&Capture>) -> Result<mc3e::Mc3eClient, LinkError> {
    let client = match link.protocol.family() {
        Family::Mc3e => link::connect_mc3e(link)?,
        _ => return Err(LinkError::Family { protocol: link.protocol, wanted: "MC protocol (mc3e, mc4e)" }),
    };
    if let Some(c) = capture {
        c.keep(client.recorder());
    }
    Ok(client)
}

async fn modbus_only(
    link: &LinkConfig,
    capture: Option<&Capture>,
) -> Result<modbus::ModbusClient, LinkError> {
    let client = link::connect_modbus(link).await?;
    if let Some(c) = capture {
        c.keep(client.recorder());
    }
    Ok(client)
}

/// `NAME VALUE` lines; with `json`, one object of them (`keyed`) or an array of
/// `{"address", "value"}` as `read` prints.
pub fn say(json: bool, pairs: Vec<(String, String)>, keyed: bool) {
    if json && keyed {
        let map: serde_json::Map<_, _> =
            pairs.into_iter().map(|(k, v)| (k, serde_json::Value::String(v))).collect();
        crate::cli::say(serde_json::Value::Object(map));
    } else if json {
        let list: Vec<_> =
            pairs.into_iter().map(|(a, v)| serde_json::json!({ "address": a, "value": v })).collect();
        crate::cli::say(serde_json::Value::Array(list));
    } else {
        for (name, value) in pairs {
            crate::cli::say(format!("{name} {value}"));
        }
    }
}

/// Refuses a poll of a request that is asked once.
pub fn once(polling: bool, what: &str) -> anyhow::Result<()> {
    if polling {
        bail!("--interval and --count repeat reads; {what} is asked once");
    }
    Ok(())
}
