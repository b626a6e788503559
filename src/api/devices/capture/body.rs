//! The bodies of the capture downloads: a device's capture built part by part on a thread
//! of its own while the client reads it, at most `server.capture_downloads` at once
//! ([`take`]); an alarm's file read from the disk as it goes out. The reasons are in the
//! parent module's doc.

use std::sync::Arc;

use axum::body::Body;
use axum::http::StatusCode;
use bytes::Bytes;
use futures::Stream;
use tokio::io::AsyncReadExt;
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};

use crate::api::error::ApiError;
use crate::capture::Reader;

/// Seconds a refused download is told to wait (`Retry-After`): a build of the default
/// 4 MiB ring takes a fraction of a second, one of a 64 MiB ring a few.
const RETRY_AFTER_SECS: u64 = 2;

/// Bytes of an alarm's file read at a time.
const FILE_PART: usize = 64 * 1024;

/// A place taken among the capture builds (`server.capture_downloads`): the build holds
/// it until it ends (finished, or its client gone).
pub struct Place {
    _permit: OwnedSemaphorePermit,
}

/// A place among `places` for one more build, or 429 `capture_busy` with `Retry-After`.
pub fn take(places: &Arc<Semaphore>) -> Result<Place, ApiError> {
    places.clone().try_acquire_owned().map(|_permit| Place { _permit }).map_err(|_| {
        let message = format!(
            "as many captures as server.capture_downloads allows are being built; try again in {RETRY_AFTER_SECS} s"
        );
        ApiError::new(StatusCode::TOO_MANY_REQUESTS, "capture_busy", message).retry_after(RETRY_AFTER_SECS)
    })
}

/// What the building thread hands the body.
enum Part {
    /// The next bytes of the file.
    Bytes(Bytes),
    /// The file is complete.
    End,
}

/// The body of a capture that a thread of its own builds from `reader`, holding `place`
/// until it ends. The thread hands over one part at a time (one waits in the channel while
/// the next is built) and stops when the body is dropped (its client went away). A body
/// whose thread stopped before the file was complete ends in an error, so the client sees
/// a broken download rather than a short file.
pub fn build(mut reader: Reader, place: Place) -> std::io::Result<Body> {
    let (parts, received) = mpsc::channel::<Part>(1);
    std::thread::Builder::new().name("rackd-capture".into()).spawn(move || {
        let _place = place;
        lower_priority();
        let sent = crate::capture::write_from(&mut reader, |part| {
            parts
                .blocking_send(Part::Bytes(Bytes::from(part)))
                .map_err(|_| std::io::ErrorKind::BrokenPipe.into())
        });
        match sent {
            Ok(frames) => {
                let _ = parts.blocking_send(Part::End);
                tracing::debug!(frames, "capture sent");
            }
            Err(_) => tracing::debug!("capture download ended by its client"),
        }
    })?;
    Ok(Body::from_stream(stream(received)))
}

/// The parts as a body's stream: an error if the sender stops before [`Part::End`].
fn stream(received: mpsc::Receiver<Part>) -> impl Stream<Item = std::io::Result<Bytes>> + Send {
    futures::stream::unfold(Some(received), |state| async move {
        let mut received = state?;
        match received.recv().await {
            Some(Part::Bytes(bytes)) => Some((Ok(bytes), Some(received))),
            Some(Part::End) => None,
            None => Some((Err(std::io::Error::other("the capture's build stopped before its end")), None)),
        }
    })
}

/// Lowers the calling thread's priority (nice 10): a build takes the CPU the devices and
/// the API leave. Nothing happens where the system refuses (never for one's own thread).
fn lower_priority() {
    #[cfg(target_os = "linux")]
    if let Err(e) = rustix::process::setpriority_process(Some(rustix::thread::gettid()), 10) {
        tracing::debug!(error = %e, "capture build: the thread's priority stays");
    }
}

/// The body of an alarm's capture file, read [`FILE_PART`] bytes at a time as it goes out.
pub fn file(file: tokio::fs::File) -> Body {
    let parts = futures::stream::unfold(Some(file), |state| async move {
        let mut file = state?;
        let mut part = Vec::with_capacity(FILE_PART);
        match (&mut file).take(FILE_PART as u64).read_to_end(&mut part).await {
            Ok(0) => None,
            Ok(_) => Some((Ok(Bytes::from(part)), Some(file))),
            Err(e) => Some((Err(e), None)),
        }
    });
    Body::from_stream(parts)
}
