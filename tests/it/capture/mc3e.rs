//! MC protocol 3E and 4E frames over TCP (on the dissector's default port) and UDP (found by
//! its heuristic), decoded by `contrib/wireshark/mc3e.lua`.

use rackd::capture::{Annotations, Link, Transport, Verdict};
use rackd::protocols::mc3e::request::{Command, Request};
use rackd::protocols::mc3e::response::{ErrorInfo, Outcome, Response};
use rackd::protocols::mc3e::{Device, Route, TypeName};

use super::{Frames, assert_clean, assert_comments, decode, job};

const FIELDS: [&str; 17] = [
    "mc3e.frame",
    "mc3e.serial",
    "mc3e.network",
    "mc3e.pc",
    "mc3e.module_io",
    "mc3e.timer",
    "mc3e.command",
    "mc3e.subcommand",
    "mc3e.device_code",
    "mc3e.head",
    "mc3e.points",
    "mc3e.word",
    "mc3e.register",
    "mc3e.bit",
    "mc3e.end_code",
    "mc3e.error.command",
    "mc3e.model",
];

fn request(serial: Option<u16>, command: Command) -> Vec<u8> {
    Request { serial, route: Route::default(), monitor_timer: 5, command }.encode()
}

fn response(serial: Option<u16>, outcome: Outcome) -> Vec<u8> {
    Response { serial, route: Route::default(), outcome }.encode()
}

fn words(values: &[u16]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn mc3e_and_mc4e_over_tcp_with_the_cranes_register_names() {
    let link = Link::Ip {
        transport: Transport::Tcp,
        local: "10.0.0.1:40000".parse().unwrap(),
        remote: "10.0.0.9:8000".parse().unwrap(),
    };
    let crane_block: Vec<u16> = (0..40).map(|i| 1000 + i).collect();
    let task = vec![17, 2, 2, 0, 1, 1, 1, 5, 3, 2];
    let mut frames = Frames::default();
    frames
        .sent(request(None, Command::ReadWords { device: Device::D, start: 200, count: 40 }), job(3))
        .received(
            response(None, Outcome::Ok(words(&crane_block))),
            Annotations { verdict: Some(Verdict::Ok), ..job(3) },
        )
        .sent(
            request(Some(0x1234), Command::WriteWords { device: Device::D, start: 8, values: task.clone() }),
            Annotations { task: Some(17), retry: 1, ..job(3) },
        )
        .received(response(Some(0x1234), Outcome::Ok(Vec::new())), Annotations::default())
        .sent(
            request(None, Command::ReadWords { device: Device::D, start: 1000, count: 2000 }),
            Annotations::default(),
        )
        .received(
            response(
                None,
                Outcome::Failed {
                    end_code: 0xC051,
                    info: Some(ErrorInfo { route: Route::default(), command: 0x0401, subcommand: 0 }),
                    trailing: Vec::new(),
                },
            ),
            Annotations { note: "points out of range".into(), ..Annotations::default() },
        )
        .sent(
            request(
                None,
                Command::WriteBits { device: Device::Y, start: 0x1A, values: vec![true, false, true] },
            ),
            Annotations::default(),
        )
        .received(response(None, Outcome::Ok(Vec::new())), Annotations::default())
        .sent(request(Some(7), Command::ReadTypeName), Annotations::default())
        .received(response(Some(7), Outcome::Ok(TypeName::default().encode())), Annotations::default());
    let packets = decode(&link, &frames, &[], &FIELDS);

    let read = &packets[0];
    assert_eq!(
        FIELDS[..11].iter().map(|f| read.get(f)).collect::<Vec<_>>(),
        ["3E", "", "0", "0xff", "0x03ff", "5", "0x0401", "0x0000", "0xa8", "200", "40"]
    );
    let answer = &packets[1];
    assert_eq!(answer.get("mc3e.end_code"), "0x0000");
    let expect: Vec<String> = crane_block.iter().map(u16::to_string).collect();
    assert_eq!(answer.all("mc3e.word"), expect);
    let names = answer.all("mc3e.register");
    assert_eq!([names[0], names[21], names[25]], ["D200 heartbeat", "D221 lift axis position", "D225 ACK"]);

    let write = &packets[2];
    assert_eq!([write.get("mc3e.frame"), write.get("mc3e.serial")], ["4E", "4660"]);
    assert_eq!(
        [write.get("mc3e.command"), write.get("mc3e.head"), write.get("mc3e.points")],
        ["0x1401", "8", "10"]
    );
    assert_eq!(write.all("mc3e.word"), task.iter().map(u16::to_string).collect::<Vec<_>>());
    assert_eq!(write.all("mc3e.register")[..2], ["D8 task number", "D9 mode"]);
    assert_eq!([packets[3].get("mc3e.serial"), packets[3].get("mc3e.end_code")], ["4660", "0x0000"]);

    assert_eq!([packets[4].get("mc3e.head"), packets[4].get("mc3e.points")], ["1000", "2000"]);
    let refusal = &packets[5];
    assert_eq!([refusal.get("mc3e.end_code"), refusal.get("mc3e.error.command")], ["0xc051", "0x0401"]);
    assert!(refusal.all("_ws.expert.message").contains(&"The PLC refused the request"));

    let bits = &packets[6];
    assert_eq!(
        [bits.get("mc3e.subcommand"), bits.get("mc3e.device_code"), bits.get("mc3e.head")],
        ["0x0001", "0x9d", "26"]
    );
    assert_eq!(bits.all("mc3e.bit"), ["1", "0", "1"]);
    assert_eq!([packets[8].get("mc3e.command"), packets[9].get("mc3e.model")], ["0x0101", "Q03UDVCPU"]);

    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);
}

#[test]
fn mc4e_over_udp_is_found_on_any_port() {
    let link = Link::Ip {
        transport: Transport::Udp,
        local: "10.0.0.1:41000".parse().unwrap(),
        remote: "10.0.0.9:5010".parse().unwrap(),
    };
    let mut frames = Frames::default();
    frames
        .sent(request(Some(1), Command::ReadWords { device: Device::ZR, start: 70000, count: 2 }), job(9))
        .received(response(Some(1), Outcome::Ok(words(&[5, 6]))), job(9))
        .received(
            response(Some(1), Outcome::Ok(words(&[5, 6]))),
            Annotations { verdict: Some(Verdict::StaleReply), ..job(9) },
        );
    let packets = decode(&link, &frames, &[], &FIELDS);
    assert_eq!(
        [packets[0].get("mc3e.frame"), packets[0].get("mc3e.device_code"), packets[0].get("mc3e.head")],
        ["4E", "0xb0", "70000"]
    );
    assert_eq!(packets[1].all("mc3e.word"), ["5", "6"]);
    assert_eq!(packets[1].all("mc3e.register"), ["ZR70000", "ZR70001"]);
    assert_eq!(packets[2].get("mc3e.end_code"), "0x0000");
    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);
}

/// A recorder keeps what each read returned: a frame cut over two reads, or two frames in
/// one. Over TCP the dissector reassembles them as Wireshark does for its own protocols.
#[test]
fn mc3e_frames_cut_or_joined_in_tcp_segments_are_reassembled() {
    let link = Link::Ip {
        transport: Transport::Tcp,
        local: "10.0.0.1:40001".parse().unwrap(),
        remote: "10.0.0.9:8000".parse().unwrap(),
    };
    let read = request(Some(1), Command::ReadWords { device: Device::D, start: 0, count: 2 });
    let (head, tail) = read.split_at(5);
    let mut both = response(Some(1), Outcome::Ok(words(&[11, 12])));
    both.extend(response(Some(2), Outcome::Ok(words(&[21, 22]))));
    let mut frames = Frames::default();
    frames
        .sent(head.to_vec(), Annotations::default())
        .sent(tail.to_vec(), Annotations::default())
        .sent(
            request(Some(2), Command::ReadWords { device: Device::D, start: 21, count: 2 }),
            Annotations::default(),
        )
        .received(
            both,
            Annotations {
                verdict: Some(Verdict::StaleReply),
                note: "serial 1 was late".into(),
                ..Annotations::default()
            },
        );
    let packets = decode(&link, &frames, &[], &FIELDS);
    assert_eq!(packets[0].get("mc3e.frame"), "", "half a frame waits for the rest");
    assert_eq!(
        [packets[1].get("mc3e.serial"), packets[1].get("mc3e.head"), packets[1].get("mc3e.points")],
        ["1", "0", "2"]
    );
    assert_eq!(packets[3].all("mc3e.serial"), ["1", "2"]);
    assert_eq!(packets[3].all("mc3e.word"), ["11", "12", "21", "22"]);
    assert_eq!(
        packets[3].all("mc3e.register"),
        ["D0 heartbeat", "D1 reserved", "D21 STB", "D22 task completion acknowledged"]
    );
    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);
}
