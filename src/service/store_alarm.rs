//! The `store` alarm: raised while the store cannot commit, naming why, and cleared once a
//! commit succeeds again ([`crate::store::fault`]).
//!
//! The alarm is a record like any other, so while the store cannot commit, its own record
//! cannot either. The watch tries again every [`RETRY`] while the fault lasts, and each try is a
//! commit: the first that goes through both records the alarm and, by succeeding, clears
//! the fault, after which the clearing is recorded too. The history then shows the spell
//! (the alarm's text says since when, the log each failed commit); `/readyz`,
//! `GET /api/v1/health`, the API's 503s and `/metrics` tell it live meanwhile, from memory.
//! The tries also notice a disk that has room again when nothing else is sent to the
//! writer.

use std::time::Duration;

use crate::domain::AlarmKind;
use crate::domain::time::from_ms;
use crate::store::alarms::NewAlarm;
use crate::store::fault::{Fault, StoreFault};
use crate::store::writer::{Record, Writer};

/// What a person does about a `store` alarm.
pub const ACTION: &str = "Free space on the disk that holds the database, or bring the database back \
     (a read-only filesystem, a failing disk, a PostgreSQL server that does not answer). rackd records \
     nothing meanwhile and holds the machines where they are; it goes on by itself once a commit \
     succeeds.";

/// How often the alarm's record is tried again while the store cannot commit.
pub const RETRY: Duration = Duration::from_secs(1);

/// The device the alarm is on: `store`, or `store:NODE` on a cluster's node (each node has
/// its own writer and sees its own commits fail).
pub fn device(node: Option<&str>) -> String {
    node.map_or_else(|| "store".to_owned(), |n| format!("store:{n}"))
}

/// Follows `fault` until the writer stops, recording the alarm on `device`. A spell is
/// recorded even when it is over before its alarm could be (raised, then cleared at once).
pub async fn watch(fault: StoreFault, writer: Writer, device: String) {
    let mut changes = fault.subscribe();
    // The spell seen and not yet recorded, and the code of the alarm recorded active.
    let (mut unrecorded, mut raised): (Option<Fault>, Option<u16>) = (None, None);
    loop {
        let now = *changes.borrow_and_update();
        if let Some(f) = now.filter(|f| raised != Some(f.cause.code())) {
            unrecorded = Some(f);
        }
        let done = match (unrecorded, now, raised) {
            (Some(f), _, _) => match writer.record(Record::AlarmRaised(alarm(&device, f))).await {
                Ok(()) => {
                    let old = raised.replace(f.cause.code()).filter(|old| *old != f.cause.code());
                    unrecorded = None;
                    match old {
                        Some(old) => clear(&writer, &device, old).await,
                        None => true,
                    }
                }
                Err(_) => false,
            },
            (None, None, Some(code)) => {
                let cleared = clear(&writer, &device, code).await;
                if cleared {
                    raised = None;
                }
                cleared
            }
            _ => {
                if changes.changed().await.is_err() {
                    return;
                }
                true
            }
        };
        if !done {
            if !writer.is_running() {
                return;
            }
            tokio::time::sleep(RETRY).await;
        }
    }
}

/// The alarm for `fault`.
fn alarm(device: &str, fault: Fault) -> NewAlarm {
    let since = from_ms(fault.since_ms)
        .format(&time::format_description::well_known::Rfc3339)
        .unwrap_or_else(|_| fault.since_ms.to_string());
    NewAlarm {
        device: device.to_owned(),
        kind: AlarmKind::Store,
        code: fault.cause.code(),
        class: AlarmKind::Store.class(),
        text: format!("the store cannot commit since {since}: {}", fault.cause.words()),
        detail: Some(format!("cause {}", fault.cause.as_str())),
        action: Some(ACTION.to_owned()),
    }
}

/// Records the clearing of the alarm of `code`; whether it was recorded.
async fn clear(writer: &Writer, device: &str, code: u16) -> bool {
    let record = Record::AlarmCleared { device: device.to_owned(), key: (AlarmKind::Store, code) };
    writer.record(record).await.is_ok()
}
