//! The top level of the JSON files a user writes (parts, plans), checked before serde reads
//! them: serde's derived structs also take an array (as the fields in order), so a plan given
//! as its list of steps was refused "invalid type: map, expected a string", naming the wrong
//! thing.

/// What the top level of `text` is when it is not a JSON object (`"an array"`, `"a string"`,
/// `"a number"`, `"true or false"`, `"null"`); `None` for an object, and for text serde's own
/// error describes better (empty, not JSON).
pub(crate) fn not_an_object(text: &str) -> Option<&'static str> {
    let t = text.trim_start_matches('\u{feff}').trim_start();
    let mut chars = t.chars();
    // Only what the start shows for sure: a word like `nope` or `-x` is not JSON at all.
    match (chars.next()?, chars.next()) {
        ('[', _) => Some("an array"),
        ('"', _) => Some("a string"),
        ('0'..='9', _) | ('-', Some('0'..='9')) => Some("a number"),
        _ if t.starts_with("true") || t.starts_with("false") => Some("true or false"),
        _ if t.starts_with("null") => Some("null"),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::not_an_object;

    #[test]
    fn names_a_top_level_that_is_not_an_object() {
        assert_eq!(not_an_object("  {\"steps\": []}"), None);
        assert_eq!(not_an_object("\u{feff}{}"), None);
        assert_eq!(not_an_object("[{\"freq_hz\": 60}]"), Some("an array"));
        assert_eq!(not_an_object("\n\"x\""), Some("a string"));
        assert_eq!(not_an_object("-3"), Some("a number"));
        assert_eq!(not_an_object("true"), Some("true or false"));
        assert_eq!(not_an_object("null"), Some("null"));
        assert_eq!(not_an_object(""), None);
        assert_eq!(not_an_object("<svg/>"), None);
        // Not JSON: serde's own error says where, rather than a guess from the first letter.
        for garbage in ["nope", "foo", "-x", "t"] {
            assert_eq!(not_an_object(garbage), None, "{garbage}");
        }
    }
}
