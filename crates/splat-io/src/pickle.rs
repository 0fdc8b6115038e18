//! The part of Python's pickle format (protocols 2 to 5, `Lib/pickle.py` and PEP 3154) that a
//! PyTorch checkpoint's `data.pkl` uses, read into a tree of [`Value`]s without running
//! anything: a global is kept as its name, a call (`REDUCE`, `NEWOBJ`) as the callable's name
//! and its arguments, and a persistent id (`BINPERSID`, how `torch.save` refers to a tensor's
//! storage) as its value. The reader of the tree decides what a call means. Any other opcode is
//! refused by name, with its byte offset.

use std::collections::HashMap;

/// A pickled value.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Value>),
    List(Vec<Value>),
    /// A dict, or an `OrderedDict` (a call of `collections.OrderedDict` with no arguments, as
    /// pickle writes one), its items in order.
    Dict(Vec<(Value, Value)>),
    /// A global by module and name, unresolved.
    Global(String, String),
    /// A call of a global with arguments (a tuple), not made.
    Call(Box<Value>, Box<Value>),
    /// An object made by a call and given a state (`BUILD`: its attributes, as the object's
    /// `__getstate__` gave them), neither run.
    Built(Box<Value>, Box<Value>),
    /// A persistent id: what the pickler's `persistent_id` returned.
    Persistent(Box<Value>),
    /// A list or dict met again (a memo reference), by its memo key: the memo holds copies,
    /// not Python's shared objects, so the copy may be stale (a list is memoized before its
    /// items are appended). Kept as a mark, so that only a reader that needs it fails.
    Shared(u32),
}

impl Value {
    /// The value of `key` in a dict.
    pub(crate) fn get(&self, key: &str) -> Option<&Value> {
        let Value::Dict(items) = self else { return None };
        items.iter().find(|(k, _)| matches!(k, Value::Str(s) if s == key)).map(|(_, v)| v)
    }

    /// The state an object was built with.
    pub(crate) fn state(&self) -> Option<&Value> {
        if let Value::Built(_, state) = self { Some(state) } else { None }
    }

    /// A dict's string keys.
    pub(crate) fn keys(&self) -> Vec<&str> {
        let Value::Dict(items) = self else { return Vec::new() };
        items.iter().filter_map(|(k, _)| if let Value::Str(s) = k { Some(s.as_str()) } else { None }).collect()
    }
}

/// What sits on the machine's stack: a value, or a mark (`MARK`).
enum Slot {
    Value(Value),
    Mark,
}

/// The pickle machine: its input, the read position, the stack and the memo.
struct Machine<'b> {
    bytes: &'b [u8],
    at: usize,
    stack: Vec<Slot>,
    memo: HashMap<u32, Value>,
}

/// Unpickle `bytes`: the value `STOP` leaves.
pub(crate) fn load(bytes: &[u8]) -> Result<Value, String> {
    let mut m = Machine { bytes, at: 0, stack: Vec::new(), memo: HashMap::new() };
    loop {
        let at = m.at;
        let op = m.take(1)?[0];
        if op == b'.' {
            return m.pop().map_err(|e| format!("pickle: STOP at byte {at}: {e}"));
        }
        m.step(op).map_err(|e| format!("pickle: opcode 0x{op:02x} at byte {at}: {e}"))?;
    }
}

impl<'b> Machine<'b> {
    fn take(&mut self, n: usize) -> Result<&'b [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("pickle: the data ends at byte {} inside a value", self.bytes.len()))?;
        let bytes: &'b [u8] = self.bytes;
        self.at = end;
        Ok(&bytes[end - n..end])
    }

    fn u8(&mut self) -> Result<usize, String> {
        Ok(usize::from(self.take(1)?[0]))
    }

    fn u16(&mut self) -> Result<usize, String> {
        let b = self.take(2)?;
        Ok(usize::from(u16::from_le_bytes([b[0], b[1]])))
    }

    fn u32(&mut self) -> Result<usize, String> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    }

    fn u64(&mut self) -> Result<usize, String> {
        let b = self.take(8)?;
        usize::try_from(u64::from_le_bytes(std::array::from_fn(|k| b[k]))).map_err(|_| "a length past memory".into())
    }

    fn line(&mut self) -> Result<String, String> {
        let rest = &self.bytes[self.at..];
        let end = rest.iter().position(|&b| b == b'\n').ok_or("a line without its end")?;
        let text = String::from_utf8_lossy(&rest[..end]).into_owned();
        self.at += end + 1;
        Ok(text)
    }

    fn text(&mut self, n: usize) -> Result<String, String> {
        String::from_utf8(self.take(n)?.to_vec()).map_err(|_| "a string that is not UTF-8".into())
    }

    fn push(&mut self, v: Value) {
        self.stack.push(Slot::Value(v));
    }

    fn pop(&mut self) -> Result<Value, String> {
        match self.stack.pop() {
            Some(Slot::Value(v)) => Ok(v),
            Some(Slot::Mark) => Err("a mark where a value was expected".into()),
            None => Err("an empty stack".into()),
        }
    }

    /// The values above the last mark, the mark removed.
    fn pop_mark(&mut self) -> Result<Vec<Value>, String> {
        let mark = self.stack.iter().rposition(|s| matches!(s, Slot::Mark)).ok_or("no mark to pop to")?;
        let values = self.stack.split_off(mark + 1);
        self.stack.pop();
        Ok(values
            .into_iter()
            .map(|s| if let Slot::Value(v) = s { v } else { unreachable!("after the last mark") })
            .collect())
    }

    fn top(&mut self) -> Result<&mut Value, String> {
        match self.stack.last_mut() {
            Some(Slot::Value(v)) => Ok(v),
            _ => Err("no value on the stack".into()),
        }
    }

    fn memo_put(&mut self, key: u32) -> Result<(), String> {
        let v = self.top()?.clone();
        self.memo.insert(key, v);
        Ok(())
    }

    /// A memoized value again: a copy of it, or [`Value::Shared`] for a list or dict (which
    /// may have changed since it was stored). The splats of a checkpoint share only globals,
    /// strings and tuples; its optimizer's state may share more.
    fn memo_get(&mut self, key: u32) -> Result<(), String> {
        let v = self.memo.get(&key).ok_or_else(|| format!("memo entry {key} was never stored"))?;
        let v = if matches!(v, Value::List(_) | Value::Dict(_)) { Value::Shared(key) } else { v.clone() };
        self.push(v);
        Ok(())
    }

    /// Set `items` (key, value pairs) on the dict at the top of the stack.
    fn set_items(&mut self, items: Vec<Value>) -> Result<(), String> {
        if !items.len().is_multiple_of(2) {
            return Err("an odd number of keys and values".into());
        }
        let Value::Dict(dict) = self.top()? else { return Err("items set on something not a dict".into()) };
        let mut items = items.into_iter();
        while let (Some(k), Some(v)) = (items.next(), items.next()) {
            match dict.iter_mut().find(|(key, _)| *key == k) {
                Some(entry) => entry.1 = v,
                None => dict.push((k, v)),
            }
        }
        Ok(())
    }

    fn append(&mut self, items: Vec<Value>) -> Result<(), String> {
        let Value::List(list) = self.top()? else { return Err("items appended to something not a list".into()) };
        list.extend(items);
        Ok(())
    }

    /// A call of `callable` with `args`: an `OrderedDict()` or a `defaultdict(factory)`
    /// becomes the dict it makes (its items follow), any other call stays a call.
    fn call(callable: Value, args: Value) -> Value {
        match (&callable, &args) {
            (Value::Global(module, name), Value::Tuple(a))
                if module == "collections"
                    && ((name == "OrderedDict" && a.is_empty()) || (name == "defaultdict" && a.len() <= 1)) =>
            {
                Value::Dict(Vec::new())
            }
            _ => Value::Call(Box::new(callable), Box::new(args)),
        }
    }

    fn step(&mut self, op: u8) -> Result<(), String> {
        match op {
            0x80 => {
                let protocol = self.u8()?;
                if !(2..=5).contains(&protocol) {
                    return Err(format!("protocol {protocol} (2 to 5 are read)"));
                }
            }
            0x95 => {
                self.u64()?; // FRAME: a length hint
            }
            b'(' => self.stack.push(Slot::Mark),
            b'N' => self.push(Value::None),
            0x88 => self.push(Value::Bool(true)),
            0x89 => self.push(Value::Bool(false)),
            b'J' => {
                let b = self.take(4)?;
                self.push(Value::Int(i64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))));
            }
            b'K' => {
                let v = self.u8()?;
                self.push(Value::Int(v as i64));
            }
            b'M' => {
                let v = self.u16()?;
                self.push(Value::Int(v as i64));
            }
            0x8a | 0x8b => {
                let n = if op == 0x8a { self.u8()? } else { self.u32()? };
                let b = self.take(n)?;
                if n > 8 {
                    return Err(format!("an integer of {n} bytes"));
                }
                // Little-endian two's complement, sign-extended from its last byte.
                let fill = if b.last().is_some_and(|&x| x & 0x80 != 0) { 0xff } else { 0 };
                let mut wide = [fill; 8];
                wide[..n].copy_from_slice(b);
                self.push(Value::Int(i64::from_le_bytes(wide)));
            }
            b'G' => {
                let b = self.take(8)?;
                self.push(Value::Float(f64::from_be_bytes(std::array::from_fn(|k| b[k]))));
            }
            b'X' | 0x8c | 0x8d => {
                let n = match op {
                    b'X' => self.u32()?,
                    0x8c => self.u8()?,
                    _ => self.u64()?,
                };
                let s = self.text(n)?;
                self.push(Value::Str(s));
            }
            b'T' | b'U' => {
                // BINSTRING, SHORT_BINSTRING: protocol 2's str of Python 2, read as text.
                let n = if op == b'T' { self.u32()? } else { self.u8()? };
                let s = String::from_utf8_lossy(self.take(n)?).into_owned();
                self.push(Value::Str(s));
            }
            b'B' | b'C' | 0x8e => {
                let n = match op {
                    b'B' => self.u32()?,
                    b'C' => self.u8()?,
                    _ => self.u64()?,
                };
                let b = self.take(n)?.to_vec();
                self.push(Value::Bytes(b));
            }
            b')' => self.push(Value::Tuple(Vec::new())),
            b']' => self.push(Value::List(Vec::new())),
            b'}' => self.push(Value::Dict(Vec::new())),
            b't' => {
                let items = self.pop_mark()?;
                self.push(Value::Tuple(items));
            }
            0x85..=0x87 => {
                let n = usize::from(op - 0x84);
                let len = self.stack.len();
                if len < n || self.stack[len - n..].iter().any(|s| matches!(s, Slot::Mark)) {
                    return Err(format!("a tuple of {n} without {n} values"));
                }
                let items = self.stack.split_off(len - n);
                let items = items.into_iter().map(|s| if let Slot::Value(v) = s { v } else { unreachable!() });
                self.push(Value::Tuple(items.collect()));
            }
            b'l' => {
                let items = self.pop_mark()?;
                self.push(Value::List(items));
            }
            b'd' => {
                let items = self.pop_mark()?;
                self.push(Value::Dict(Vec::new()));
                self.set_items(items)?;
            }
            b'a' => {
                let v = self.pop()?;
                self.append(vec![v])?;
            }
            b'e' => {
                let items = self.pop_mark()?;
                self.append(items)?;
            }
            b's' => {
                let v = self.pop()?;
                let k = self.pop()?;
                self.set_items(vec![k, v])?;
            }
            b'u' => {
                let items = self.pop_mark()?;
                self.set_items(items)?;
            }
            b'c' => {
                let (module, name) = (self.line()?, self.line()?);
                self.push(Value::Global(module, name));
            }
            0x93 => {
                let name = self.pop()?;
                let module = self.pop()?;
                let (Value::Str(module), Value::Str(name)) = (module, name) else {
                    return Err("STACK_GLOBAL of values that are not strings".into());
                };
                self.push(Value::Global(module, name));
            }
            b'R' | 0x81 => {
                let args = self.pop()?;
                let callable = self.pop()?;
                self.push(Self::call(callable, args));
            }
            b'b' => {
                // BUILD: an object made by a call keeps its state (a config's values are read
                // from it); a dict's (an nn.Module state dict's `_metadata`) is not read.
                let state = self.pop()?;
                let top = self.top()?;
                if let Value::Call(..) = top {
                    let made = std::mem::replace(top, Value::None);
                    *top = Value::Built(Box::new(made), Box::new(state));
                }
            }
            b'Q' => {
                let id = self.pop()?;
                self.push(Value::Persistent(Box::new(id)));
            }
            // BINPUT, LONG_BINPUT, MEMOIZE; BINGET, LONG_BINGET.
            b'q' | b'r' | 0x94 => {
                let key = match op {
                    b'q' => self.u8()?,
                    b'r' => self.u32()?,
                    _ => self.memo.len(),
                };
                self.memo_put(key as u32)?;
            }
            b'h' | b'j' => {
                let key = if op == b'h' { self.u8()? } else { self.u32()? };
                self.memo_get(key as u32)?;
            }
            b'0' => {
                self.stack.pop().ok_or("POP of an empty stack")?;
            }
            _ => return Err("an opcode a checkpoint's arrays do not need, which this reader does not run".into()),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
    }

    fn s(v: &str) -> Value {
        Value::Str(v.into())
    }

    /// CPython 3's `pickle.dumps({"a": [1, -2, 300, 70000, 2**40, -2**40], "b": (1.5, "x", True,
    /// None, b"\x00\x01"), "c": ()}, protocol=P)` for P = 2 and 4: the integers in every width,
    /// a float, a short string, the constants, bytes (protocol 2 writes them as a call of
    /// `_codecs.encode`), the memo and protocol 4's frames.
    #[test]
    fn cpythons_pickles_read_as_their_values() {
        let p2 = "80027d71002858010000006171015d7102284b014afeffffff4d2c014a701101008a060000000000018a060000000000ff65580100000062710328473ff80000000000005801000000787104884e635f636f646563730a656e636f64650a710558020000000001710658060000006c6174696e31710786710852710974710a580100000063710b29752e";
        let p4 = "8004954c000000000000007d94288c0161945d94284b014afeffffff4d2c014a701101008a060000000000018a060000000000ff658c01629428473ff80000000000008c017894884e430200019474948c01639429752e";
        let ints = Value::List([1, -2, 300, 70000, 1 << 40, -(1 << 40)].map(Value::Int).to_vec());
        let encode = Value::Global("_codecs".into(), "encode".into());
        let latin1 = Value::Call(Box::new(encode), Box::new(Value::Tuple(vec![s("\u{0}\u{1}"), s("latin1")])));
        for (protocol, pickle, bytes) in [(2, p2, latin1), (4, p4, Value::Bytes(vec![0, 1]))] {
            let b = Value::Tuple(vec![Value::Float(1.5), s("x"), Value::Bool(true), Value::None, bytes]);
            let expected = Value::Dict(vec![(s("a"), ints.clone()), (s("b"), b), (s("c"), Value::Tuple(vec![]))]);
            assert_eq!(load(&hex(pickle)), Ok(expected), "protocol {protocol}");
        }
    }

    /// `{"o": OrderedDict([("k", 1), ("j", (2, 3))])}` (a call of `collections.OrderedDict`, then
    /// its items), and `[t, t]` of one tuple (the second a memo reference).
    #[test]
    fn ordered_dicts_and_memo_references_read() {
        let od = "80027d710058010000006f710163636f6c6c656374696f6e730a4f726465726564446963740a7102295271032858010000006b71044b0158010000006a71054b024b0386710675732e";
        let items = vec![(s("k"), Value::Int(1)), (s("j"), Value::Tuple(vec![Value::Int(2), Value::Int(3)]))];
        assert_eq!(load(&hex(od)), Ok(Value::Dict(vec![(s("o"), Value::Dict(items))])));
        let memo = "80025d71002858010000007371018571026802652e";
        let t = Value::Tuple(vec![s("s")]);
        assert_eq!(load(&hex(memo)), Ok(Value::List(vec![t.clone(), t])));
    }

    /// `types.SimpleNamespace(a=1)` (a call, then BUILD with its state) keeps its state, as a
    /// config object's is read; `defaultdict(list, {"k": [1]})` reads as the dict it is.
    #[test]
    fn built_objects_keep_their_state() {
        let namespace =
            "80026374797065730a53696d706c654e616d6573706163650a7100295271017d710258010000006171034b0173622e";
        let made = Value::Call(
            Box::new(Value::Global("types".into(), "SimpleNamespace".into())),
            Box::new(Value::Tuple(vec![])),
        );
        let state = Value::Dict(vec![(s("a"), Value::Int(1))]);
        let built = load(&hex(namespace)).unwrap();
        assert_eq!(built, Value::Built(Box::new(made), Box::new(state.clone())));
        assert_eq!(built.state(), Some(&state));
        let defaultdict = "800263636f6c6c656374696f6e730a64656661756c74646963740a7100635f5f6275696c74696e5f5f0a6c6973740a710185710252710358010000006b71045d71054b0161732e";
        let items = vec![(s("k"), Value::List(vec![Value::Int(1)]))];
        assert_eq!(load(&hex(defaultdict)), Ok(Value::Dict(items)));
    }

    /// A list shared by two places (`[l, l]`, the second a memo reference) reads as a mark of
    /// the sharing, not as a stale copy; an opcode no checkpoint needs (protocol 4's EMPTY_SET)
    /// and every truncation of a pickle are refused, never read wrong or panicking.
    #[test]
    fn what_it_cannot_read_is_refused() {
        let shared = load(&hex("80025d7100285d71014b01616801652e")).unwrap();
        assert_eq!(shared, Value::List(vec![Value::List(vec![Value::Int(1)]), Value::Shared(1)]));
        let set = load(&[0x80, 0x04, 0x8f, b'.']).unwrap_err();
        assert!(set.contains("opcode 0x8f at byte 2"), "{set}");
        let p2 = hex(
            "80027d710058010000006f710163636f6c6c656374696f6e730a4f726465726564446963740a7102295271032858010000006b71044b0158010000006a71054b024b0386710675732e",
        );
        for len in 0..p2.len() {
            assert!(load(&p2[..len]).is_err(), "{len} bytes");
        }
        assert!(load(&[0x80, 0x01, b'N', b'.']).unwrap_err().contains("protocol 1"));
    }
}
