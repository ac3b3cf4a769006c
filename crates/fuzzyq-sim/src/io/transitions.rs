//! Logged transitions as CSV: one transition per line, `E + D + E + 1` numbers separated by
//! commas, `x_1..x_E, u_1..u_D, x'_1..x'_E, r` (state, joint action vector, successor,
//! reward), with an optional header line (a first line that is not all numbers). This is the
//! file `fuzzyq train --learner learned-model --transitions FILE.csv` reads.

use std::path::Path;

use crate::error::ConfigError;
use crate::learn::samples::Transitions;

/// Reads transitions of states of length `state_dim` and action vectors of `action_dim`;
/// errors name the file, the line and what is wrong.
pub fn read_transitions_csv(
    path: &Path,
    state_dim: usize,
    action_dim: usize,
) -> Result<Transitions, ConfigError> {
    let text = crate::fs::read_text(path, crate::fs::MAX_TRANSITIONS_BYTES).map_err(|e| {
        ConfigError::invalid(
            "transitions",
            format!("cannot read {}: {e}", path.display()),
        )
    })?;
    parse(&text, state_dim, action_dim).map_err(|reason| {
        ConfigError::invalid("transitions", format!("{}: {reason}", path.display()))
    })
}

fn parse(text: &str, e: usize, d: usize) -> Result<Transitions, String> {
    let width = 2 * e + d + 1;
    let mut out = Transitions::new(e, d);
    let mut row = Vec::with_capacity(width);
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        row.clear();
        let parsed: Result<Vec<f64>, _> =
            line.split(',').map(|f| f.trim().parse::<f64>()).collect();
        match parsed {
            Ok(values) => row.extend(values),
            Err(_) if i == 0 => continue, // a header
            Err(err) => return Err(format!("line {}: not a number ({err})", i + 1)),
        }
        if row.len() != width {
            return Err(format!(
                "line {}: {} values, expected {width} (state {e}, action {d}, next state {e}, \
                 reward 1)",
                i + 1,
                row.len()
            ));
        }
        if let Some(k) = row.iter().position(|v| !v.is_finite()) {
            return Err(format!("line {}: value {} is not finite", i + 1, k + 1));
        }
        out.push(
            &row[..e],
            &row[e..e + d],
            &row[e + d..2 * e + d],
            row[width - 1],
        );
    }
    if out.is_empty() {
        return Err("no transitions".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_rows_with_or_without_a_header_and_names_bad_lines() {
        let t = parse("x,v,u,x2,v2,r\n1,2,3,4,5,6\n\n0.5,0,1,0.6,0,0\n", 2, 1).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(
            t.get(0),
            (&[1.0, 2.0][..], &[3.0][..], &[4.0, 5.0][..], 6.0)
        );
        let t2 = parse("1,2,3,4,5,6\n", 2, 1).unwrap();
        assert_eq!(t2.len(), 1);
        assert!(
            parse("1,2,3\n", 2, 1)
                .unwrap_err()
                .contains("line 1: 3 values, expected 6")
        );
        assert!(
            parse("1,2,3,4,5,6\n1,2,x,4,5,6\n", 2, 1)
                .unwrap_err()
                .contains("line 2")
        );
        assert!(
            parse("1,2,3,4,5,inf\n", 2, 1)
                .unwrap_err()
                .contains("not finite")
        );
        assert!(
            parse("header only\n", 2, 1)
                .unwrap_err()
                .contains("no transitions")
        );
    }
}
