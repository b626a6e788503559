//! Cursor paging never skips or repeats a job, even while jobs are being added.

use std::collections::BTreeSet;

use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use crate::support::*;

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn paging_while_adding_has_no_gaps_or_repeats(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let first: Vec<_> = (0..250).map(|i| store(&format!("P{i}"))).collect();
    app.post("/api/v1/jobs/batch", &json!({"jobs": first})).await;

    let writer = {
        let (client, url) = (app.client.clone(), app.url("/api/v1/jobs"));
        tokio::spawn(async move {
            for i in 0..100 {
                client.post(&url).json(&store(&format!("Q{i}"))).send().await.unwrap();
            }
        })
    };
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    loop {
        let path = match &cursor {
            Some(c) => format!("/api/v1/jobs?limit=7&cursor={c}"),
            None => "/api/v1/jobs?limit=7".to_owned(),
        };
        let (status, page) = app.get(&path).await;
        assert_eq!(status, 200);
        seen.extend(page["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()));
        match page["next_cursor"].as_str() {
            Some(c) => cursor = Some(c.to_owned()),
            None => break,
        }
    }
    writer.await.unwrap();
    let unique: BTreeSet<_> = seen.iter().copied().collect();
    assert_eq!(unique.len(), seen.len(), "no job twice");
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "in order");
    assert!(seen.len() >= 250, "every job that existed before paging began: {}", seen.len());
    let max = *seen.last().unwrap();
    assert_eq!(unique, (1..=max).collect(), "no gap");
}
