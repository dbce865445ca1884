//! Left and right in bone names: the side a name carries and its mirror name. Shared by
//! the skeleton embedding (the template's pairs) and the fit's recovery (mirrored limbs).

/// The name of `name`'s other side, when its name carries one: `_l`/`_r`, `.L`/`.R`,
/// `left`/`Left` and `right`/`Right` anywhere as a separate token.
pub fn other_side(name: &str) -> Option<String> {
    let tokens: Vec<&str> = name.split(['_', '.', '-', ' ']).collect();
    let swapped: Vec<String> = tokens
        .iter()
        .map(|t| match *t {
            "l" => "r".into(),
            "r" => "l".into(),
            "L" => "R".into(),
            "R" => "L".into(),
            "left" => "right".into(),
            "right" => "left".into(),
            "Left" => "Right".into(),
            "Right" => "Left".into(),
            t => t.to_string(),
        })
        .collect();
    if swapped.iter().zip(&tokens).all(|(a, b)| a == b) {
        return None;
    }
    // Rebuild with the original separators.
    let mut out = String::with_capacity(name.len());
    let mut rest = name;
    for (token, new) in tokens.iter().zip(&swapped) {
        out.push_str(new);
        rest = &rest[token.len()..];
        if let Some(sep) = rest.chars().next() {
            out.push(sep);
            rest = &rest[sep.len_utf8()..];
        }
    }
    Some(out)
}

/// Whether `token` names the left side.
pub fn is_left_token(token: &str) -> bool {
    matches!(token, "l" | "L" | "left" | "Left")
}

/// Whether `name` is on the left side (its side token is `l`, `L`, `left` or `Left`).
pub fn is_left(name: &str) -> bool {
    name.split(['_', '.', '-', ' ']).any(is_left_token)
}
