//! The Modbus client (master): one device, any transport, retries in one place.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use tokio::sync::Mutex;

use super::config::{ModbusConfig, Transport};
use super::device_id::{DeviceIdPage, DeviceObject, ReadDeviceIdCode};
use super::link::{Counters, Exchange, Link, RtuLink, TcpLink, UdpLink};
use super::pdu::{self, Request, Response};
use super::rtu;
use crate::capture::{Recorder, SerialProtocol};
use crate::protocols::PlcError;
use crate::protocols::transport::{
    Attempt, Backoff, ByteStream, Endpoint, Guard, LinkHealth, LinkStats, Retry, RetryPolicy, StreamLink,
    recorder_for,
};

/// Counters of a client's traffic, for diagnostics and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClientStats {
    /// Requests asked of the client (after splitting).
    pub requests: u64,
    /// Frames sent, retries included.
    pub sends: u64,
    /// Frames or datagrams received and dropped as not answering the current request
    /// (stale transaction id, other unit, broken datagram, leftover input).
    pub dropped: u64,
}

/// A Modbus master for one device. Requests from concurrent callers are sent one at a
/// time. Implements [`crate::protocols::PlcMemory`] (see `memory.rs`).
pub struct ModbusClient {
    config: ModbusConfig,
    policy: RetryPolicy,
    link: Mutex<Link>,
    counters: Arc<Counters>,
    recorder: Option<Arc<Recorder>>,
}

/// The flight recorder for `config`'s link, if it has capture limits.
fn recorder(config: &ModbusConfig, endpoint: &Endpoint) -> Option<Arc<Recorder>> {
    let line = (!config.transport.is_mbap()).then_some(SerialProtocol::ModbusRtu);
    recorder_for(config.capture, endpoint, line)
}

impl ModbusClient {
    /// A client for `config`. Nothing is sent yet: a UDP socket is bound, a TCP connection or
    /// serial port is opened on the first request (and reopened after it is lost), so a
    /// device that is down when the client is built does not fail construction.
    pub async fn connect(config: ModbusConfig) -> Result<Self, PlcError> {
        config.transport.check_unit(config.unit).map_err(PlcError::OutOfRange)?;
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        let described = match config.transport {
            Transport::Udp => Endpoint::Udp { peer: config.address.clone(), local: None },
            Transport::Tcp | Transport::RtuOverTcp => Endpoint::Tcp(config.address.clone()),
            Transport::RtuSerial => {
                Endpoint::Serial { path: config.address.clone(), settings: config.serial }
            }
        };
        let recorder = recorder(&config, &described);
        let counters = Arc::new(Counters::new(LinkHealth::new(policy).recording(recorder.clone())));
        let replies = config.replies();
        let mut link = match config.transport {
            Transport::Udp => {
                let mut udp = UdpLink::new(config.address.clone(), config.quirks, replies, counters.clone());
                udp.set_recorder(recorder.clone());
                udp.open(config.timeout).await.map_err(|e| e.once(&policy))?;
                Link::Udp(udp)
            }
            Transport::Tcp => {
                Link::Tcp(TcpLink::new(config.address.clone(), config.quirks, replies, counters.clone()))
            }
            // A serial gateway hands a late reply to whichever connection is open: a line.
            Transport::RtuOverTcp => {
                let link =
                    StreamLink::new(Endpoint::Tcp(config.address.clone()), Backoff::default(), Guard::Wait);
                Link::Rtu(RtuLink::new(link, rtu::silence(0), counters.clone()))
            }
            Transport::RtuSerial => {
                let endpoint = Endpoint::Serial { path: config.address.clone(), settings: config.serial };
                let link = StreamLink::new(endpoint, Backoff::default(), Guard::Wait);
                Link::Rtu(RtuLink::new(link, rtu::silence(config.serial.baud), counters.clone()))
            }
        };
        link.set_recorder(recorder.clone());
        Ok(ModbusClient { config, policy, link: Mutex::new(link), counters, recorder })
    }

    /// An RTU client over a stream the caller already opened (a pty in tests, a port
    /// opened with special settings). The stream cannot be reopened if it fails. It carries
    /// RTU frames whatever `config.transport` says (an MBAP transport is taken as RTU).
    pub fn rtu_over_stream(
        mut config: ModbusConfig,
        stream: impl ByteStream + 'static,
    ) -> Result<Self, PlcError> {
        if config.transport.is_mbap() {
            config.transport = Transport::RtuSerial;
        }
        config.transport.check_unit(config.unit).map_err(PlcError::OutOfRange)?;
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        let endpoint = Endpoint::given(stream);
        let recorder = recorder(&config, &endpoint);
        let counters = Arc::new(Counters::new(LinkHealth::new(policy).recording(recorder.clone())));
        let mut link = StreamLink::new(endpoint, Backoff::default(), Guard::Wait);
        link.set_recorder(recorder.clone());
        let link = Link::Rtu(RtuLink::new(link, rtu::silence(config.serial.baud), counters.clone()));
        Ok(ModbusClient { config, policy, link: Mutex::new(link), counters, recorder })
    }

    /// A client over carriers the caller dials (the seeded wire simulation of the tests),
    /// framed as `config.transport` says: datagrams for UDP, connections for TCP (each
    /// dial a new one), a line for RTU (each dial the same line again).
    pub fn over(
        config: ModbusConfig,
        dial: Arc<dyn crate::protocols::transport::Dial>,
    ) -> Result<Self, PlcError> {
        config.transport.check_unit(config.unit).map_err(PlcError::OutOfRange)?;
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        let counters = Arc::new(Counters::new(LinkHealth::new(policy)));
        let replies = config.replies();
        let endpoint = Endpoint::Dial(dial);
        let link = match config.transport {
            Transport::Udp => {
                let guard = Guard::of(replies, true);
                let link =
                    crate::protocols::transport::DatagramLink::over(endpoint, Backoff::default(), guard);
                Link::Udp(UdpLink::over(link, config.quirks, replies, counters.clone()))
            }
            Transport::Tcp => Link::Tcp(TcpLink::over(endpoint, config.quirks, replies, counters.clone())),
            Transport::RtuSerial | Transport::RtuOverTcp => {
                let link = StreamLink::new(endpoint, Backoff::default(), Guard::Wait);
                Link::Rtu(RtuLink::new(link, rtu::silence(config.serial.baud), counters.clone()))
            }
        };
        Ok(ModbusClient { config, policy, link: Mutex::new(link), counters, recorder: None })
    }

    /// The configuration this client was built with.
    pub fn config(&self) -> &ModbusConfig {
        &self.config
    }

    /// Traffic counters so far.
    pub fn stats(&self) -> ClientStats {
        ClientStats {
            requests: self.counters.requests.load(Ordering::Relaxed),
            sends: self.counters.sends.load(Ordering::Relaxed),
            dropped: self.counters.dropped.load(Ordering::Relaxed),
        }
    }

    /// The link's health (adaptive timeout, degraded flag, counters).
    pub fn link_stats(&self) -> LinkStats {
        self.counters.health.stats()
    }

    /// The link's flight recorder, when the configuration asked for one.
    pub fn recorder(&self) -> Option<Arc<Recorder>> {
        self.recorder.clone()
    }

    /// Sends one request (within the per-function limits) to the configured unit under the
    /// retry policy ([`RetryPolicy`]): exception replies are returned at once as
    /// [`PlcError::Device`]; timeouts, lost connections and malformed replies are retried.
    /// Over RTU a write to unit 0 is broadcast: nothing is awaited and the expected echo is
    /// returned. Over TCP and UDP unit 0 addresses the device itself and is answered.
    pub async fn call(&self, request: &Request) -> Result<Response, PlcError> {
        request.check().map_err(PlcError::OutOfRange)?;
        self.send(request).await
    }

    /// Like [`ModbusClient::call`], but a read (01..04) is sent with whatever count and
    /// address it has, 0 and past the per-function limits included, to test a device's
    /// limits: the device's exception (usually 03, illegal data value) comes back as
    /// [`PlcError::Device`], and a reply that does not fit the count is malformed. Other
    /// requests are checked as by `call`, since their counts set their own byte counts.
    pub async fn call_unchecked(&self, request: &Request) -> Result<Response, PlcError> {
        let read = matches!(
            request,
            Request::ReadCoils { .. }
                | Request::ReadDiscreteInputs { .. }
                | Request::ReadHoldingRegisters { .. }
                | Request::ReadInputRegisters { .. }
        );
        if !read {
            request.check().map_err(PlcError::OutOfRange)?;
        }
        self.send(request).await
    }

    async fn send(&self, request: &Request) -> Result<Response, PlcError> {
        let unit = self.config.unit;
        let mut pdu_bytes = Vec::with_capacity(260);
        request.encode(&mut pdu_bytes);
        Counters::bump(&self.counters.requests);
        let mut link = self.link.lock().await;
        let ex = Exchange { unit, request, pdu: &pdu_bytes };
        if unit == 0 && !self.config.transport.is_mbap() {
            if !request.is_write() {
                return Err(PlcError::OutOfRange("unit 0 (broadcast) is for writes only"));
            }
            return match link.send_only(&ex, &Attempt::single(&self.policy)).await {
                Ok(()) => Ok(echo_of(request)),
                Err(e) => Err(e.once(&self.policy)),
            };
        }
        let mut retry = Retry::start(&self.counters.health, "modbus");
        while let Some(attempt) = retry.next_attempt() {
            match link.attempt(&ex, &attempt).await {
                Ok((response, answered)) => {
                    match answered {
                        Some(number) => retry.succeeded_by(number),
                        None => retry.succeeded(),
                    }
                    return Ok(response);
                }
                Err(e) => retry.failed(e)?,
            }
        }
        Err(retry.spent())
    }

    /// Reads the device identification objects of `category` (basic, regular or extended
    /// stream access), following "more follows" and the next object id across as many
    /// requests as the device needs. With [`ReadDeviceIdCode::Individual`] it reads object
    /// 0 alone; see [`ModbusClient::read_device_object`] for any other. A device that does
    /// not implement function 43 answers exception 01, surfaced as [`PlcError::Device`].
    pub async fn read_device_identification(
        &self,
        category: ReadDeviceIdCode,
    ) -> Result<Vec<DeviceObject>, PlcError> {
        let mut objects = Vec::new();
        let mut from = 0u8;
        // Each page must move forward, so 256 requests read every possible object.
        for _ in 0..256 {
            let request = Request::ReadDeviceId { code: category, object_id: from };
            let Response::ReadDeviceId(page) = self.call(&request).await? else {
                return Err(PlcError::Malformed("not a device identification reply"));
            };
            objects.extend(page.objects);
            match page.next {
                None => return Ok(objects),
                Some(next) if next > from => from = next,
                Some(_) => {
                    return Err(PlcError::Malformed(
                        "device identification: next object id does not advance",
                    ));
                }
            }
        }
        Err(PlcError::Malformed("device identification: more than 256 pages"))
    }

    /// Reads one device identification object (individual access, code 04). A device
    /// without that object answers exception 02, surfaced as [`PlcError::Device`].
    pub async fn read_device_object(&self, id: u8) -> Result<DeviceObject, PlcError> {
        let request = Request::ReadDeviceId { code: ReadDeviceIdCode::Individual, object_id: id };
        let Response::ReadDeviceId(page) = self.call(&request).await? else {
            return Err(PlcError::Malformed("not a device identification reply"));
        };
        match <[DeviceObject; 1]>::try_from(page.objects) {
            Ok([object]) if object.id == id => Ok(object),
            _ => Err(PlcError::Malformed("device identification: not the one object asked for")),
        }
    }

    /// Reads the FIFO queue whose count register is at `address` (function 24): the queued
    /// registers, oldest first, at most 31. A queue of more than 31 is exception 03 from
    /// the device ([`PlcError::Device`]).
    pub async fn read_fifo_queue(&self, address: u16) -> Result<Vec<u16>, PlcError> {
        match self.call(&Request::ReadFifoQueue { address }).await? {
            Response::ReadFifoQueue(words) => Ok(words),
            _ => Err(PlcError::Malformed("not a FIFO queue reply")),
        }
    }

    /// Diagnostics (08) `sub_function` with data 0000: the device's answer, a register or
    /// counter (0002 diagnostic register, 000B bus messages, 000C bus communication
    /// errors, 000D bus exceptions, 000E server messages, 000F server no responses), or
    /// the echoed 0000 for 000A (clear counters). A sub-function the device lacks comes
    /// back as exception 01 ([`PlcError::Device`]); one rackd does not know is refused
    /// before sending.
    pub async fn diagnostic(&self, sub_function: u16) -> Result<u16, PlcError> {
        if !pdu::diag_known(sub_function) {
            return Err(PlcError::OutOfRange("diagnostics sub-function not one of 0000, 0002, 000A..000F"));
        }
        match self.call(&Request::Diagnostics { sub_function, data: 0 }).await? {
            Response::Diagnostics { data, .. } => Ok(data),
            _ => Err(PlcError::Malformed("not a diagnostics reply")),
        }
    }

    /// A link check: diagnostics 08 sub-function 0000 (return query data), which the
    /// device must echo.
    pub async fn link_check(&self) -> Result<(), PlcError> {
        let data = rand::random();
        let request = Request::Diagnostics { sub_function: pdu::DIAG_RETURN_QUERY_DATA, data };
        self.call(&request).await.map(|_| ())
    }
}

/// The reply a device would have sent to a write; used for broadcasts, which get none.
fn echo_of(request: &Request) -> Response {
    match request {
        Request::WriteSingleCoil { address, value } => {
            Response::WriteSingleCoil { address: *address, value: *value }
        }
        Request::WriteSingleRegister { address, value } => {
            Response::WriteSingleRegister { address: *address, value: *value }
        }
        Request::WriteMultipleCoils { address, values } => {
            Response::WriteMultipleCoils { address: *address, count: values.len() as u16 }
        }
        Request::WriteMultipleRegisters { address, values } => {
            Response::WriteMultipleRegisters { address: *address, count: values.len() as u16 }
        }
        Request::Diagnostics { sub_function, data } => {
            Response::Diagnostics { sub_function: *sub_function, data: *data }
        }
        // Reads are refused before broadcasting; an empty answer keeps this total.
        Request::ReadFifoQueue { .. } => Response::ReadFifoQueue(Vec::new()),
        Request::ReadDeviceId { code, .. } => Response::ReadDeviceId(DeviceIdPage {
            code: *code,
            conformity: 0,
            next: None,
            objects: Vec::new(),
        }),
        Request::ReadCoils { .. } | Request::ReadDiscreteInputs { .. } => Response::ReadCoils(Vec::new()),
        Request::ReadHoldingRegisters { .. } | Request::ReadInputRegisters { .. } => {
            Response::ReadHoldingRegisters(Vec::new())
        }
    }
}
