//! Vectors written as text on a command line or in a form: `"x,y,z"`. The CLI, the viewer and
//! the Embree peer read their `--eye`, `--target` and `--up` options with these, so that one
//! spelling and one message serve every front end.

use glam::Vec3;

/// Three finite numbers `x,y,z` (spaces around each allowed).
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> =
        s.split(',').map(|c| c.trim().parse::<f32>()).collect::<Result<_, _>>().map_err(|e| format!("'{s}': {e}"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("'{s}' is not three finite numbers x,y,z")),
    }
}

/// A direction `x,y,z`: three finite numbers, not all zero (a world up, a light's direction).
pub fn parse_direction(s: &str) -> Result<Vec3, String> {
    match parse_vec3(s)? {
        v if v == Vec3::ZERO => Err(format!("'{s}' is not a direction: give a non-zero x,y,z")),
        v => Ok(v),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vectors_parse_and_bad_ones_say_why() {
        assert_eq!(parse_vec3(" 1, -2.5 ,3").unwrap(), Vec3::new(1.0, -2.5, 3.0));
        assert_eq!(parse_direction("0,-1,0").unwrap(), Vec3::NEG_Y);
        for (bad, want) in [("1,2", "three finite"), ("1,2,3,4", "three finite"), ("1,x,3", "'1,x,3'")] {
            assert!(parse_vec3(bad).unwrap_err().contains(want), "{bad}");
        }
        assert!(parse_vec3("1,inf,0").unwrap_err().contains("finite"));
        assert!(parse_direction("0,0,0").unwrap_err().contains("not a direction"));
    }
}
