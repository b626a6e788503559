//! The flight recorder against the real simulators: the frames it kept are exactly the
//! traffic the client's counters and the simulator's count, with the verdicts marked, and
//! tshark reads the file they make.

use std::time::Duration;

use rackd::capture::{Direction, Frame, Link, Transport, Verdict};
use rackd::protocols::PlcMemory;
use rackd::protocols::faults::Fault;
use rackd::protocols::link::{connect, connect_modbus};
use rackd::protocols::transport::LinkStats;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::sim::shelf::{ShelfProtocol, ShelfSim, ShelfSimOptions};

use super::{Frames, assert_comments, decode};

fn count(frames: &[Frame], direction: Direction, verdict: Option<Verdict>) -> u64 {
    frames.iter().filter(|f| f.direction == direction && f.annotations.verdict == verdict).count() as u64
}

fn received(frames: &[Frame], verdict: Verdict) -> u64 {
    count(frames, Direction::Received, Some(verdict))
}

/// The frames agree with the link's counters: every request and retry sent once, every
/// retry marked with its number, each drop with its reason.
fn assert_matches_counters(frames: &[Frame], stats: &LinkStats) {
    let sent: Vec<&Frame> = frames.iter().filter(|f| f.direction == Direction::Sent).collect();
    assert_eq!(sent.len() as u64, stats.requests + stats.retries, "{stats:?}");
    let retries = sent.iter().filter(|f| f.annotations.retry > 0).count() as u64;
    assert_eq!(retries, stats.retries);
    assert!(
        sent.iter()
            .filter(|f| f.annotations.retry > 0)
            .all(|f| f.annotations.verdict == Some(Verdict::Retry))
    );
    assert_eq!(received(frames, Verdict::Ok), stats.requests, "every request answered once");
    assert_eq!(received(frames, Verdict::StaleReply), stats.stale);
    assert_eq!(received(frames, Verdict::ForeignReply) + received(frames, Verdict::WrongUnit), stats.foreign);
    assert_eq!(received(frames, Verdict::Malformed) + received(frames, Verdict::CrcError), stats.malformed);
    assert_eq!(count(frames, Direction::Received, None), 0, "every received frame judged");
}

#[tokio::test]
async fn modbus_udp_drops_late_duplicate_foreign_and_garbage_replies_are_all_recorded() {
    let options = ShelfSimOptions::for_protocol(ShelfProtocol::ModbusUdp);
    let sim = ShelfSim::start("127.0.0.1:0", options).await.unwrap();
    let address = sim.local_addr().unwrap();
    let mut link = sim.link(&address.to_string());
    link.timeout = Duration::from_millis(100);
    link.tuning.min_timeout = link.timeout;
    link.retries = 3;
    let client = connect_modbus(&link).await.unwrap();
    let recorder = client.recorder().expect("capture is on by default");
    let faults = sim.faults();
    // A drop (retried after a timeout), a late reply (taken; the retry's answer comes
    // after it and is dropped on the next request: a late answer to rackd's own request,
    // stale), a wrong transaction id (one rackd never sent: foreign; dropped, then a
    // retry), a duplicate (the copy dropped on the next request), noise before a reply.
    faults
        .push(Fault::Drop)
        .push(Fault::Delay(Duration::from_millis(150)))
        .push(Fault::WrongId)
        .push(Fault::Duplicate)
        .push(Fault::Garbage(vec![1, 2, 3]));
    let at = client.parse_address(sim.base()).unwrap();
    let requests = 12u64;
    for _ in 0..requests - 2 {
        client.read_words(&at, 4).await.unwrap();
    }
    // Every late answer has arrived before the last two requests read it.
    tokio::time::sleep(Duration::from_millis(300)).await;
    for _ in 0..2 {
        client.write_words(&at, &[0]).await.unwrap();
    }
    let frames = recorder.frames(None);
    let stats = client.link_stats();
    assert_matches_counters(&frames, &stats);
    assert_eq!(stats.requests, requests);
    assert!(
        stats.retries >= 2
            && stats.timeouts >= 2
            && stats.foreign == 1
            && stats.stale >= 1
            && stats.malformed == 1,
        "{stats:?}"
    );
    // The simulator saw every frame sent; it answered all but the dropped one, the
    // duplicate twice, plus the noise datagram: every one of them was read.
    let sent = count(&frames, Direction::Sent, None) + count(&frames, Direction::Sent, Some(Verdict::Retry));
    assert_eq!(sent, faults.requests_seen());
    let replies = frames.iter().filter(|f| f.direction == Direction::Received).count() as u64;
    assert_eq!(replies, faults.requests_seen() - 1 + 1 + 1);
    assert_eq!(recorder.stats().timeouts, stats.timeouts);
    let after_timeout = frames.iter().filter(|f| f.annotations.note == "after a timeout").count() as u64;
    assert_eq!(after_timeout, stats.timeouts, "each timeout here was retried");
    assert!(frames.windows(2).all(|w| w[0].time_us <= w[1].time_us), "in time order");
    let Link::Ip { transport: Transport::Udp, local, remote } = recorder.link() else {
        panic!("{:?}", recorder.link())
    };
    assert_eq!(remote, address);
    assert_ne!(local.port(), 0);

    let frames = Frames(frames);
    let port = format!("udp.port=={},mbudp", address.port());
    let packets = decode(&recorder.link(), &frames, &["-d", &port], &["mbtcp.trans_id", "udp.dstport"]);
    assert_comments(&packets, &frames);
    assert!(
        packets
            .iter()
            .filter(|p| p.get("udp.dstport") == address.port().to_string())
            .all(|p| !p.get("mbtcp.trans_id").is_empty())
    );
}

#[tokio::test]
async fn mc3e_tcp_clean_traffic_and_a_reconnect_are_recorded_with_the_new_endpoints() {
    let options = CraneSimOptions { step: Duration::from_millis(10), ..Default::default() };
    let sim = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let mut link = rackd::protocols::link::LinkConfig::new(
        rackd::protocols::Protocol::Mc3e,
        sim.local_addr().to_string(),
    );
    link.timeout = Duration::from_millis(300);
    let plc = connect(&link).await.unwrap();
    let recorder = plc.recorder().expect("capture is on by default");
    let at = plc.parse_address("D0").unwrap();
    plc.serving(Some((42, 7)));
    plc.write_words(&at, &[5]).await.unwrap();
    plc.serving(None);
    plc.read_words(&at, 2).await.unwrap();
    let Link::Ip { local: first, .. } = recorder.link() else { panic!() };
    sim.drop_link();
    plc.read_words(&at, 2).await.unwrap();
    plc.read_words(&at, 2).await.unwrap();
    let Link::Ip { transport, local, remote } = recorder.link() else { panic!() };
    assert_eq!((transport, remote), (Transport::Tcp, sim.local_addr()));
    assert_ne!(local.port(), first.port(), "a reconnect: a new local port");
    let frames = recorder.frames(None);
    let stats = plc.link_stats();
    assert_matches_counters(&frames, &stats);
    assert_eq!((stats.requests, stats.retries), (4, 1), "{stats:?}");
    let retry = frames.iter().find(|f| f.annotations.retry == 1).unwrap();
    assert_eq!(retry.annotations.note, "after a lost connection");
    let served: Vec<String> = frames[..2].iter().map(|f| f.annotations.comment()).collect();
    assert_eq!(served, ["job 42, task 7", "job 42, task 7, verdict: ok"]);
    assert!(frames[2..].iter().all(|f| f.annotations.job.is_none()));

    let frames = Frames(frames);
    // The MC dissector finds its frames on any port by their subheader.
    let packets = decode(&recorder.link(), &frames, &[], &["tcp.srcport"]);
    assert_comments(&packets, &frames);
}
