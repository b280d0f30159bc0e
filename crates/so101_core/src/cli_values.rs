//! Values the binaries take on their command lines, parsed once for all of them.

/// `x,y,z` in metres (a point of the scene: each within 100 m).
pub fn parse_point(text: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|part| part.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{text:?} is not x,y,z"))?;
    match values.as_slice() {
        [x, y, z] if values.iter().all(|v| v.is_finite() && v.abs() < 100.0) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "{text:?} is not x,y,z (three finite numbers in metres)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_and_nonsense_is_refused() {
        assert_eq!(parse_point("0.1, -0.2,0.75"), Ok([0.1, -0.2, 0.75]));
        assert!(parse_point("1,2").is_err());
        assert!(parse_point("1,2,NaN").is_err());
        assert!(parse_point("a,b,c").is_err());
    }
}
