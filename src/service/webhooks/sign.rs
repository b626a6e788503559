//! The Standard Webhooks signature (<https://www.standardwebhooks.com>): `v1,` and the
//! base64 of HMAC-SHA256, keyed with the subscription's secret, over
//! `{webhook-id}.{webhook-timestamp}.{body}`. A receiver verifies it with the
//! specification's own libraries (`standardwebhooks` for Python and TypeScript, Svix's),
//! given the same `whsec_...` secret.

use base64::Engine;
use hmac::{Hmac, KeyInit, Mac};
use sha2::Sha256;

/// The headers of one delivery.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Signed {
    /// `webhook-id`: the same for every try of one event to one subscription.
    pub id: String,
    /// `webhook-timestamp`: Unix seconds of this try.
    pub timestamp: i64,
    /// `webhook-signature`.
    pub signature: String,
}

/// Signs `body` as message `id` sent at `timestamp` (Unix seconds).
pub fn sign(key: &[u8], id: &str, timestamp: i64, body: &[u8]) -> Signed {
    let signature =
        format!("v1,{}", base64::engine::general_purpose::STANDARD.encode(mac(key, id, timestamp, body)));
    Signed { id: id.to_owned(), timestamp, signature }
}

/// Whether `signature` (a header value: one or more space-separated `v1,...`) signs
/// `body` as message `id` at `timestamp`: what a receiver checks (the tests' receiver and
/// `bench webhooks` use it).
pub fn verify(key: &[u8], id: &str, timestamp: i64, body: &[u8], signature: &str) -> bool {
    signature.split(' ').filter_map(|s| s.strip_prefix("v1,")).any(|b64| {
        let Ok(given) = base64::engine::general_purpose::STANDARD.decode(b64) else { return false };
        let mut mac = keyed(key);
        feed(&mut mac, id, timestamp, body);
        mac.verify_slice(&given).is_ok()
    })
}

fn keyed(key: &[u8]) -> Hmac<Sha256> {
    <Hmac<Sha256> as KeyInit>::new_from_slice(key).expect("HMAC takes a key of any length")
}

fn feed(mac: &mut Hmac<Sha256>, id: &str, timestamp: i64, body: &[u8]) {
    mac.update(id.as_bytes());
    mac.update(b".");
    mac.update(timestamp.to_string().as_bytes());
    mac.update(b".");
    mac.update(body);
}

fn mac(key: &[u8], id: &str, timestamp: i64, body: &[u8]) -> Vec<u8> {
    let mut mac = keyed(key);
    feed(&mut mac, id, timestamp, body);
    mac.finalize().into_bytes().to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::webhooks::decode_secret;

    /// The example of the Standard Webhooks specification's reference libraries.
    #[test]
    fn signs_as_the_specification_s_example() {
        let key = decode_secret("whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw").unwrap();
        let body = br#"{"test": 2432232314}"#;
        let signed = sign(&key, "msg_p5jXN8AQM9LWM0D4loKWxJek", 1614265330, body);
        assert_eq!(signed.signature, "v1,g0hM9SsE+OTPJTGt/tmIKtSyZlE3uFJELVlNIOLJ1OE=");
        assert!(verify(&key, &signed.id, 1614265330, body, &format!("v1,bm90IGl0 {}", signed.signature)));
        assert!(!verify(&key, &signed.id, 1614265331, body, &signed.signature));
        assert!(!verify(&key, &signed.id, 1614265330, b"{}", &signed.signature));
    }
}
