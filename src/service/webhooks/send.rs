//! One try to deliver one event: the signed POST and what came of it, as the delivery log
//! records it.

use std::time::Instant;

use futures::StreamExt;

use super::sign;
use crate::config::WebhookConfig;
use crate::domain::time::now_ms;
use crate::store::webhooks::Delivery;

/// The most of an answer's body kept in a delivery's error.
const EXCERPT: usize = 200;

/// POSTs `body`, event `seq` as message `id`, to `config`'s URL, signed with `key`: the
/// `attempt`th try.
pub(super) async fn post(
    client: &reqwest::Client,
    config: &WebhookConfig,
    key: &[u8],
    (seq, id, body): (i64, &str, &bytes::Bytes),
    attempt: i64,
) -> Delivery {
    let timestamp = now_ms() / 1000;
    let signed = sign::sign(key, id, timestamp, body);
    let started = Instant::now();
    let answer = client
        .post(&config.url)
        .header("content-type", "application/json")
        .header("webhook-id", &signed.id)
        .header("webhook-timestamp", signed.timestamp.to_string())
        .header("webhook-signature", &signed.signature)
        .body(body.clone())
        .send()
        .await;
    let (status, outcome, error) = match answer {
        Ok(answer) => {
            let status = answer.status();
            let excerpt = read_excerpt(answer).await;
            if status.is_success() {
                (Some(status.as_u16()), "delivered", None)
            } else {
                let outcome = if status == reqwest::StatusCode::GONE { "gone" } else { "failed" };
                let said = if excerpt.is_empty() { String::new() } else { format!(": {excerpt}") };
                (Some(status.as_u16()), outcome, Some(format!("answered {status}{said}")))
            }
        }
        Err(e) => (None, "failed", Some(describe(&e, config.timeout_ms))),
    };
    Delivery {
        id: 0,
        name: config.name.clone(),
        seq,
        attempt,
        status: status.map(i64::from),
        outcome: outcome.to_owned(),
        latency_ms: started.elapsed().as_millis() as i64,
        error,
        at: now_ms(),
    }
}

/// A failed request in words for the delivery log: what kind of failure, and the innermost
/// cause (never the URL, which may carry credentials).
fn describe(e: &reqwest::Error, timeout_ms: u64) -> String {
    if e.is_timeout() {
        return format!("no answer within {timeout_ms} ms");
    }
    let mut cause: &dyn std::error::Error = e;
    while let Some(inner) = cause.source() {
        cause = inner;
    }
    let what = if e.is_connect() { "could not connect" } else { "the request failed" };
    format!("{what}: {cause}")
}

/// Reads up to [`super::BODY_LIMIT`] bytes of an answer's body (so the connection can be
/// kept), and returns the first [`EXCERPT`] characters of it, printable only.
async fn read_excerpt(answer: reqwest::Response) -> String {
    let mut body = Vec::new();
    let mut stream = answer.bytes_stream();
    while let Some(Ok(chunk)) = stream.next().await {
        body.extend_from_slice(&chunk);
        if body.len() > super::BODY_LIMIT {
            break;
        }
    }
    let text = String::from_utf8_lossy(&body[..body.len().min(4 * EXCERPT)]);
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .take(EXCERPT)
        .collect::<String>()
        .trim()
        .to_owned()
}
