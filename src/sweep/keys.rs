//! Setting a dotted key of a coordinator file's TOML: `gains.k`, `emulator.latency_ms`,
//! `vehicle.3.drag_per_s` (the third `[[vehicle]]`), `vehicle.*.drag_per_s` (every one).
//! Missing tables on the way are made; whether the key means anything is the config's
//! to say (its tables refuse unknown fields). Pure.

/// Sets `key` to `value` in `doc`.
///
/// # Errors
/// An empty part, a list entered without a position or `*`, a position out of the list,
/// or a part that is a value where a table was needed; each naming the key.
pub fn set(doc: &mut toml::Table, key: &str, value: &toml::Value) -> Result<(), String> {
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(format!("{key}: an empty part in the key"));
    }
    set_in(doc, &parts, key, value)
}

fn set_in(
    table: &mut toml::Table,
    parts: &[&str],
    key: &str,
    value: &toml::Value,
) -> Result<(), String> {
    let Some((&head, rest)) = parts.split_first() else {
        return Err(format!("{key}: an empty key"));
    };
    if head == "*" || head.parse::<usize>().is_ok() {
        return Err(format!("{key}: `{head}` where a name was expected"));
    }
    if rest.is_empty() {
        if matches!(
            table.get(head),
            Some(toml::Value::Table(_) | toml::Value::Array(_))
        ) && !matches!(value, toml::Value::Table(_) | toml::Value::Array(_))
        {
            return Err(format!(
                "{key}: `{head}` is a table or a list, not a number"
            ));
        }
        table.insert(head.to_owned(), value.clone());
        return Ok(());
    }
    let entry = table
        .entry(head.to_owned())
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    match entry {
        toml::Value::Table(inner) => set_in(inner, rest, key, value),
        toml::Value::Array(list) => {
            let (&which, after) = rest.split_first().unwrap_or((&"", &[]));
            if which != "*" && which.parse::<usize>().is_err() {
                return Err(format!(
                    "{key}: `{head}` is a list: give a position from 1 (`{head}.1.…`) or `*` (`{head}.*.…`), not `{which}`"
                ));
            }
            if after.is_empty() {
                return Err(format!(
                    "{key}: `{head}` is a list: name a field of its entries"
                ));
            }
            let entries: Vec<&mut toml::Value> = if which == "*" {
                list.iter_mut().collect()
            } else {
                let n: usize = which.parse().unwrap_or(0);
                let len = list.len();
                match n.checked_sub(1).and_then(|i| list.get_mut(i)) {
                    Some(e) => vec![e],
                    None => {
                        return Err(format!("{key}: `{head}` has {len} entries, no entry {n}"));
                    }
                }
            };
            for e in entries {
                match e {
                    toml::Value::Table(inner) => set_in(inner, after, key, value)?,
                    _ => return Err(format!("{key}: an entry of `{head}` is not a table")),
                }
            }
            Ok(())
        }
        _ => Err(format!("{key}: `{head}` is a value, not a table")),
    }
}

/// A number as TOML: an integer when it is one (so that integer settings take it; a
/// float setting takes an integer too), a float otherwise.
pub fn number(v: f64) -> toml::Value {
    if v.fract() == 0.0 && v.abs() < 9.0e15 {
        toml::Value::Integer(v as i64)
    } else {
        toml::Value::Float(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> toml::Table {
        toml::from_str(
            "[gains]\nk = 5.0\n[[vehicle]]\nsystem_id = 1\ndrag_per_s = 0.0\n[[vehicle]]\nsystem_id = 2\ndrag_per_s = 0.0\n",
        )
        .unwrap()
    }

    fn at<'a>(d: &'a toml::Table, path: &[&str]) -> &'a toml::Value {
        let mut v = d.get(path[0]).unwrap();
        for p in &path[1..] {
            v = match p.parse::<usize>() {
                Ok(i) => &v.as_array().unwrap()[i],
                Err(_) => v.get(p).unwrap(),
            };
        }
        v
    }

    #[test]
    fn a_key_sets_a_table_field_one_list_entry_or_every_entry() {
        let mut d = doc();
        set(&mut d, "gains.k", &number(2.5)).unwrap();
        assert_eq!(at(&d, &["gains", "k"]), &toml::Value::Float(2.5));
        set(&mut d, "emulator.latency_ms", &number(20.0)).unwrap();
        assert_eq!(
            at(&d, &["emulator", "latency_ms"]),
            &toml::Value::Integer(20)
        );
        set(&mut d, "vehicle.2.drag_per_s", &number(0.1)).unwrap();
        assert_eq!(
            at(&d, &["vehicle", "0", "drag_per_s"]),
            &toml::Value::Float(0.0)
        );
        assert_eq!(
            at(&d, &["vehicle", "1", "drag_per_s"]),
            &toml::Value::Float(0.1)
        );
        set(&mut d, "vehicle.*.drag_per_s", &number(0.3)).unwrap();
        assert_eq!(
            at(&d, &["vehicle", "0", "drag_per_s"]),
            &toml::Value::Float(0.3)
        );
        assert_eq!(
            at(&d, &["vehicle", "1", "drag_per_s"]),
            &toml::Value::Float(0.3)
        );
    }

    #[test]
    fn a_key_that_cannot_be_set_is_refused_by_name() {
        let cases = [
            ("gains..k", "gains..k: an empty part in the key"),
            (
                "vehicle.drag_per_s",
                "give a position from 1 (`vehicle.1.…`) or `*`",
            ),
            (
                "vehicle.3.drag_per_s",
                "`vehicle` has 2 entries, no entry 3",
            ),
            ("vehicle.0.drag_per_s", "no entry 0"),
            ("vehicle.1", "`vehicle` is a list: name a field"),
            ("gains.k.x", "`k` is a value, not a table"),
            ("gains", "`gains` is a table or a list, not a number"),
            ("*.k", "`*` where a name was expected"),
        ];
        for (key, expected) in cases {
            let got = set(&mut doc(), key, &number(1.0)).unwrap_err();
            assert!(got.contains(expected), "{key}: {got}");
        }
    }

    #[test]
    fn whole_numbers_go_as_integers_and_the_rest_as_floats() {
        assert_eq!(number(3.0), toml::Value::Integer(3));
        assert_eq!(number(-2.0), toml::Value::Integer(-2));
        assert_eq!(number(0.25), toml::Value::Float(0.25));
        assert_eq!(number(1e20), toml::Value::Float(1e20));
    }
}
