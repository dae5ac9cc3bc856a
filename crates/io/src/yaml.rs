//! YAML read with its nesting bounded: serde_yaml_ng takes time growing faster than
//! the text on deeply nested flow collections (`[[[...]]]` 100,000 deep, 200 kB,
//! took ~40 s), and no metadata or calibration file nests more than a few levels.

use serde::de::DeserializeOwned;

/// The deepest nesting of flow collections (`[`, `{`) a YAML text may hold.
pub const MAX_DEPTH: usize = 64;

/// `text` as a `T`, or why not: nested deeper than [`MAX_DEPTH`], or not a `T`.
pub fn from_str<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    let depth = flow_depth(text);
    if depth > MAX_DEPTH {
        return Err(format!(
            "its collections nest {depth} deep ([ or {{ inside another), at most {MAX_DEPTH} expected"
        ));
    }
    serde_yaml_ng::from_str(text).map_err(|e| e.to_string())
}

/// The deepest nesting of `[` and `{` outside quoted scalars and comments.
fn flow_depth(text: &str) -> usize {
    let (mut depth, mut deepest) = (0usize, 0usize);
    let mut quote = None;
    let mut comment = false;
    let mut previous = '\n';
    for c in text.chars() {
        match (quote, c) {
            _ if comment => comment = c != '\n',
            (Some(q), _) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '#') if previous.is_whitespace() => comment = true,
            (None, '[' | '{') => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            (None, ']' | '}') => depth = depth.saturating_sub(1),
            _ => {}
        }
        previous = c;
    }
    deepest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_nesting_is_bounded_and_quotes_and_comments_do_not_count() {
        let deep = format!(
            "custom_data: {}{}",
            "[".repeat(100_000),
            "]".repeat(100_000)
        );
        let started = std::time::Instant::now();
        let err = from_str::<serde_yaml_ng::Value>(&deep).unwrap_err();
        assert!(err.contains("nest 100000 deep"), "{err}");
        assert!(started.elapsed().as_secs() < 1);
        let fine = "a: [[1, 2], {b: '[[[[', c: \"{{{\"}] # [[[[[[\nd: x[\n";
        assert_eq!(flow_depth(fine), 2);
        assert!(from_str::<serde_yaml_ng::Value>(fine).is_ok());
    }
}
