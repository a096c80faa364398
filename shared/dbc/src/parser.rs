//! Reads the DBC statements AutoPlug uses (and the common ones around them) into a
//! [`Database`]. Anything it does not understand is an error naming the line: silently
//! skipping part of the one source of the catalogue would be worse than refusing it.

use crate::lexer::{tokenize, Token, TokenKind};
use crate::model::*;
use crate::ParseError;

/// Parses DBC text.
pub fn parse(text: &str) -> Result<Database, ParseError> {
    let tokens = tokenize(text)?;
    let mut parser = Parser {
        tokens,
        pos: 0,
        db: Database::default(),
    };
    parser.file()?;
    Ok(parser.db)
}

struct Parser {
    tokens: Vec<Token>,
    pos: usize,
    db: Database,
}

impl Parser {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.pos)
    }

    fn next(&mut self, what: &str) -> Result<Token, ParseError> {
        match self.tokens.get(self.pos) {
            Some(t) => {
                self.pos += 1;
                Ok(t.clone())
            }
            None => {
                let (line, column) = self
                    .tokens
                    .last()
                    .map(|t| (t.line, t.column))
                    .unwrap_or((1, 1));
                Err(ParseError::new(
                    line,
                    column,
                    format!("file ends where {what} was expected"),
                ))
            }
        }
    }

    fn error_at(token: &Token, message: impl Into<String>) -> ParseError {
        ParseError::new(token.line, token.column, message)
    }

    fn expected(token: &Token, what: &str) -> ParseError {
        Self::error_at(
            token,
            format!("expected {what}, found {}", token.kind.describe()),
        )
    }

    fn punct(&mut self, c: char) -> Result<(), ParseError> {
        let t = self.next(&format!("'{c}'"))?;
        if t.kind == TokenKind::Punct(c) {
            Ok(())
        } else {
            Err(Self::expected(&t, &format!("'{c}'")))
        }
    }

    fn peek_punct(&self, c: char) -> bool {
        self.peek().is_some_and(|t| t.kind == TokenKind::Punct(c))
    }

    fn ident(&mut self, what: &str) -> Result<(String, Token), ParseError> {
        let t = self.next(what)?;
        match &t.kind {
            TokenKind::Ident(s) => Ok((s.clone(), t)),
            _ => Err(Self::expected(&t, what)),
        }
    }

    fn string(&mut self, what: &str) -> Result<String, ParseError> {
        let t = self.next(what)?;
        match t.kind {
            TokenKind::Str(s) => Ok(s),
            _ => Err(Self::expected(&t, what)),
        }
    }

    fn number_text(&mut self, what: &str) -> Result<(String, Token), ParseError> {
        let t = self.next(what)?;
        match &t.kind {
            TokenKind::Number(s) => Ok((s.clone(), t)),
            _ => Err(Self::expected(&t, what)),
        }
    }

    fn float(&mut self, what: &str) -> Result<f64, ParseError> {
        let (s, t) = self.number_text(what)?;
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| Self::error_at(&t, format!("{what}: '{s}' is not a finite number")))
    }

    fn int(&mut self, what: &str) -> Result<i64, ParseError> {
        let (s, t) = self.number_text(what)?;
        parse_int(&s).ok_or_else(|| Self::error_at(&t, format!("{what}: '{s}' is not an integer")))
    }

    fn uint(&mut self, what: &str, max: u64) -> Result<u64, ParseError> {
        let (s, t) = self.number_text(what)?;
        s.parse::<u64>().ok().filter(|v| *v <= max).ok_or_else(|| {
            Self::error_at(
                &t,
                format!("{what}: '{s}' is not a whole number from 0 to {max}"),
            )
        })
    }

    /// Consumes tokens up to and including the next `;`.
    fn semicolon(&mut self) -> Result<(), ParseError> {
        self.punct(';')
    }

    fn file(&mut self) -> Result<(), ParseError> {
        while let Some(t) = self.peek().cloned() {
            let TokenKind::Ident(keyword) = &t.kind else {
                return Err(Self::expected(&t, "a DBC keyword"));
            };
            self.pos += 1;
            match keyword.as_str() {
                "VERSION" => self.db.version = self.string("version string")?,
                "NS_" => self.new_symbols(&t)?,
                "BS_" => self.bit_timing(&t)?,
                "BU_" => self.nodes(&t)?,
                "VAL_TABLE_" => self.value_table()?,
                "BO_" => self.message(&t)?,
                "BO_TX_BU_" => self.message_transmitters()?,
                "CM_" => self.comment()?,
                "BA_DEF_" => self.attribute_definition()?,
                "BA_DEF_DEF_" => self.attribute_default()?,
                "BA_" => self.attribute()?,
                "VAL_" => self.value_descriptions()?,
                "SG_" => return Err(Self::error_at(&t, "signal 'SG_' outside a message 'BO_'")),
                other => {
                    return Err(Self::error_at(
                        &t,
                        format!("unsupported DBC statement '{other}'"),
                    ))
                }
            }
        }
        Ok(())
    }

    /// `NS_ :` followed by an indented list of symbol names.
    fn new_symbols(&mut self, ns: &Token) -> Result<(), ParseError> {
        self.punct(':')?;
        while let Some(t) = self.peek() {
            let indented = t.line > ns.line && t.column > 1;
            if indented && matches!(t.kind, TokenKind::Ident(_)) {
                self.pos += 1;
            } else {
                break;
            }
        }
        Ok(())
    }

    /// `BS_: [baudrate : BTR1 , BTR2]`, all on one line and unused by CAN 2.0 tools.
    fn bit_timing(&mut self, bs: &Token) -> Result<(), ParseError> {
        self.punct(':')?;
        while self.peek().is_some_and(|t| t.line == bs.line) {
            self.pos += 1;
        }
        Ok(())
    }

    /// `BU_: a b c` on one line.
    fn nodes(&mut self, bu: &Token) -> Result<(), ParseError> {
        self.punct(':')?;
        while let Some(t) = self.peek().cloned() {
            if t.line != bu.line {
                break;
            }
            let (name, _) = self.ident("node name")?;
            self.db.nodes.push(Node {
                name,
                ..Node::default()
            });
        }
        Ok(())
    }

    fn value_pairs(&mut self) -> Result<Vec<(i64, String)>, ParseError> {
        let mut entries = Vec::new();
        while !self.peek_punct(';') {
            let value = self.int("raw value of a value description")?;
            let text = self.string("value description")?;
            entries.push((value, text));
        }
        self.semicolon()?;
        Ok(entries)
    }

    fn value_table(&mut self) -> Result<(), ParseError> {
        let (name, _) = self.ident("value table name")?;
        let entries = self.value_pairs()?;
        self.db.value_tables.push(ValueTable { name, entries });
        Ok(())
    }

    fn message_id(&mut self) -> Result<(u32, bool), ParseError> {
        let raw = self.uint("message identifier", u64::from(u32::MAX))? as u32;
        Ok((raw & 0x1FFF_FFFF, raw & 0x8000_0000 != 0))
    }

    fn message(&mut self, bo: &Token) -> Result<(), ParseError> {
        let (id, extended) = self.message_id()?;
        let (name, _) = self.ident("message name")?;
        self.punct(':')?;
        let dlc = self.uint("message length", 64)? as u8;
        let (transmitter, _) = self.ident("transmitting node")?;
        let mut message = Message {
            id,
            extended,
            name,
            dlc,
            transmitters: if transmitter == "Vector__XXX" {
                vec![]
            } else {
                vec![transmitter]
            },
            line: bo.line,
            ..Message::default()
        };
        while self
            .peek()
            .is_some_and(|t| t.kind == TokenKind::Ident("SG_".into()))
        {
            let sg = self.next("SG_")?;
            message.signals.push(self.signal(&sg)?);
        }
        self.db.messages.push(message);
        Ok(())
    }

    /// `SG_ name [M|mN] : start|length@order sign (factor,offset) [min|max] "unit" rx,rx`
    fn signal(&mut self, sg: &Token) -> Result<Signal, ParseError> {
        let (name, _) = self.ident("signal name")?;
        let mut multiplexing = Multiplexing::None;
        if let Some(TokenKind::Ident(m)) = self.peek().map(|t| t.kind.clone()) {
            let t = self.next("multiplexer indicator")?;
            multiplexing = if m == "M" {
                Multiplexing::Multiplexer
            } else if let Some(n) = m.strip_prefix('m').and_then(|n| n.parse().ok()) {
                Multiplexing::Multiplexed(n)
            } else {
                return Err(Self::expected(
                    &t,
                    "':' or a multiplexer indicator (M or mN)",
                ));
            };
        }
        self.punct(':')?;
        let start_bit = self.uint("start bit", 511)? as u16;
        self.punct('|')?;
        let length = self.uint("signal length", 512)? as u16;
        self.punct('@')?;
        let order = self.next("byte order (0 or 1)")?;
        let byte_order = match &order.kind {
            TokenKind::Number(s) if s == "1" => ByteOrder::LittleEndian,
            TokenKind::Number(s) if s == "0" => ByteOrder::BigEndian,
            _ => {
                return Err(Self::expected(
                    &order,
                    "byte order 0 (Motorola) or 1 (Intel)",
                ))
            }
        };
        let sign = self.next("value type '+' or '-'")?;
        let signed = match sign.kind {
            TokenKind::Punct('+') => false,
            TokenKind::Punct('-') => true,
            _ => {
                return Err(Self::expected(
                    &sign,
                    "value type '+' (unsigned) or '-' (signed)",
                ))
            }
        };
        self.punct('(')?;
        let factor = self.float("factor")?;
        self.punct(',')?;
        let offset = self.float("offset")?;
        self.punct(')')?;
        self.punct('[')?;
        let min = self.float("minimum")?;
        self.punct('|')?;
        let max = self.float("maximum")?;
        self.punct(']')?;
        let unit = self.string("unit")?;
        let mut receivers = Vec::new();
        loop {
            let (rx, _) = self.ident("receiving node")?;
            if rx != "Vector__XXX" {
                receivers.push(rx);
            }
            if self.peek_punct(',') {
                self.pos += 1;
            } else {
                break;
            }
        }
        Ok(Signal {
            name,
            start_bit,
            length,
            byte_order,
            signed,
            factor,
            offset,
            min,
            max,
            unit,
            receivers,
            multiplexing,
            line: sg.line,
            ..Signal::default()
        })
    }

    fn message_mut(&mut self, id: u32, at: &Token) -> Result<&mut Message, ParseError> {
        self.db
            .messages
            .iter_mut()
            .find(|m| m.id == id)
            .ok_or_else(|| Self::error_at(at, format!("no message with identifier {id}")))
    }

    fn signal_mut(&mut self, id: u32, name: &str, at: &Token) -> Result<&mut Signal, ParseError> {
        let message = self.message_mut(id, at)?;
        let message_name = message.name.clone();
        message
            .signals
            .iter_mut()
            .find(|s| s.name == name)
            .ok_or_else(|| {
                Self::error_at(at, format!("message {message_name} has no signal '{name}'"))
            })
    }

    fn node_mut(&mut self, name: &str, at: &Token) -> Result<&mut Node, ParseError> {
        self.db
            .nodes
            .iter_mut()
            .find(|n| n.name == name)
            .ok_or_else(|| Self::error_at(at, format!("no node named '{name}' in BU_")))
    }

    /// `BO_TX_BU_ id : a,b ;`
    fn message_transmitters(&mut self) -> Result<(), ParseError> {
        let at = self.peek().cloned();
        let (id, _) = self.message_id()?;
        self.punct(':')?;
        let mut names = Vec::new();
        loop {
            names.push(self.ident("transmitting node")?.0);
            if self.peek_punct(',') {
                self.pos += 1;
            } else {
                break;
            }
        }
        self.semicolon()?;
        let at = at.expect("a token was read");
        let message = self.message_mut(id, &at)?;
        for name in names {
            if !message.transmitters.contains(&name) {
                message.transmitters.push(name);
            }
        }
        Ok(())
    }

    /// The object an attribute or comment is attached to.
    fn object_ref(&mut self) -> Result<(ObjectRef, Token), ParseError> {
        let t = self.peek().cloned().ok_or_else(|| {
            ParseError::new(0, 0, "file ends where an object or value was expected")
        })?;
        let object = match &t.kind {
            TokenKind::Ident(k) if k == "BU_" => {
                self.pos += 1;
                ObjectRef::Node(self.ident("node name")?.0)
            }
            TokenKind::Ident(k) if k == "BO_" => {
                self.pos += 1;
                ObjectRef::Message(self.message_id()?.0)
            }
            TokenKind::Ident(k) if k == "SG_" => {
                self.pos += 1;
                let (id, _) = self.message_id()?;
                ObjectRef::Signal(id, self.ident("signal name")?.0)
            }
            TokenKind::Ident(k) if k == "EV_" => {
                self.pos += 1;
                self.ident("environment variable name")?;
                ObjectRef::EnvironmentVariable
            }
            _ => ObjectRef::Network,
        };
        Ok((object, t))
    }

    /// `CM_ [BU_ n | BO_ id | SG_ id s | EV_ n] "text" ;`
    fn comment(&mut self) -> Result<(), ParseError> {
        let (object, at) = self.object_ref()?;
        let text = self.string("comment text")?;
        self.semicolon()?;
        match object {
            ObjectRef::Network => self.db.comment = Some(text),
            ObjectRef::Node(n) => self.node_mut(&n, &at)?.comment = Some(text),
            ObjectRef::Message(id) => self.message_mut(id, &at)?.comment = Some(text),
            ObjectRef::Signal(id, s) => self.signal_mut(id, &s, &at)?.comment = Some(text),
            ObjectRef::EnvironmentVariable => {
                return Err(Self::error_at(
                    &at,
                    "environment variables are not supported",
                ))
            }
        }
        Ok(())
    }

    /// `BA_DEF_ [BU_|BO_|SG_|EV_] "name" INT min max | HEX min max | FLOAT min max | STRING | ENUM "a","b" ;`
    fn attribute_definition(&mut self) -> Result<(), ParseError> {
        let object = match self.peek().map(|t| t.kind.clone()) {
            Some(TokenKind::Ident(k)) => {
                let t = self.next("object kind")?;
                match k.as_str() {
                    "BU_" => AttributeObject::Node,
                    "BO_" => AttributeObject::Message,
                    "SG_" => AttributeObject::Signal,
                    "EV_" => AttributeObject::EnvironmentVariable,
                    _ => {
                        return Err(Self::expected(
                            &t,
                            "BU_, BO_, SG_, EV_ or an attribute name",
                        ))
                    }
                }
            }
            _ => AttributeObject::Network,
        };
        let name = self.string("attribute name")?;
        let (kind_name, kind_token) = self.ident("attribute type")?;
        let kind = match kind_name.as_str() {
            "INT" => AttributeKind::Int {
                min: self.int("INT minimum")?,
                max: self.int("INT maximum")?,
            },
            "HEX" => AttributeKind::Hex {
                min: self.int("HEX minimum")?,
                max: self.int("HEX maximum")?,
            },
            "FLOAT" => AttributeKind::Float {
                min: self.float("FLOAT minimum")?,
                max: self.float("FLOAT maximum")?,
            },
            "STRING" => AttributeKind::String,
            "ENUM" => {
                let mut values = Vec::new();
                while !self.peek_punct(';') {
                    values.push(self.string("ENUM value")?);
                    if self.peek_punct(',') {
                        self.pos += 1;
                    }
                }
                AttributeKind::Enum(values)
            }
            _ => {
                return Err(Self::expected(
                    &kind_token,
                    "attribute type INT, HEX, FLOAT, STRING or ENUM",
                ))
            }
        };
        self.semicolon()?;
        self.db.attribute_definitions.push(AttributeDefinition {
            object,
            name,
            kind,
            default: None,
        });
        Ok(())
    }

    fn attribute_value(&mut self, name: &str) -> Result<AttributeValue, ParseError> {
        let t = self.next("attribute value")?;
        match &t.kind {
            TokenKind::Str(s) => Ok(AttributeValue::Str(s.clone())),
            TokenKind::Number(s) => match parse_int(s) {
                Some(v) => Ok(AttributeValue::Int(v)),
                None => s
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .map(AttributeValue::Float)
                    .ok_or_else(|| {
                        Self::error_at(&t, format!("attribute {name}: '{s}' is not a number"))
                    }),
            },
            _ => Err(Self::expected(&t, "attribute value (number or string)")),
        }
    }

    /// `BA_DEF_DEF_ "name" value ;`
    fn attribute_default(&mut self) -> Result<(), ParseError> {
        let at = self.peek().cloned();
        let name = self.string("attribute name")?;
        let value = self.attribute_value(&name)?;
        self.semicolon()?;
        let mut found = false;
        for def in self
            .db
            .attribute_definitions
            .iter_mut()
            .filter(|d| d.name == name)
        {
            def.default = Some(value.clone());
            found = true;
        }
        if !found {
            let at = at.expect("a token was read");
            return Err(Self::error_at(
                &at,
                format!("default for attribute \"{name}\", which no BA_DEF_ defines"),
            ));
        }
        Ok(())
    }

    /// `BA_ "name" [BU_ n | BO_ id | SG_ id s | EV_ n] value ;`
    fn attribute(&mut self) -> Result<(), ParseError> {
        let name_token = self.peek().cloned();
        let name = self.string("attribute name")?;
        let (object, at) = self.object_ref()?;
        let value = self.attribute_value(&name)?;
        self.semicolon()?;
        let kind = match &object {
            ObjectRef::Network => AttributeObject::Network,
            ObjectRef::Node(_) => AttributeObject::Node,
            ObjectRef::Message(_) => AttributeObject::Message,
            ObjectRef::Signal(..) => AttributeObject::Signal,
            ObjectRef::EnvironmentVariable => AttributeObject::EnvironmentVariable,
        };
        let Some(def) = self.db.attribute_definition(kind, &name).cloned() else {
            let t = name_token.expect("a token was read");
            return Err(Self::error_at(
                &t,
                format!("attribute \"{name}\" is not defined for {kind:?} objects by a BA_DEF_"),
            ));
        };
        check_attribute_value(&def, &value).map_err(|m| Self::error_at(&at, m))?;
        let entry = (name, value);
        match object {
            ObjectRef::Network => self.db.attributes.push(entry),
            ObjectRef::Node(n) => self.node_mut(&n, &at)?.attributes.push(entry),
            ObjectRef::Message(id) => self.message_mut(id, &at)?.attributes.push(entry),
            ObjectRef::Signal(id, s) => self.signal_mut(id, &s, &at)?.attributes.push(entry),
            ObjectRef::EnvironmentVariable => {
                return Err(Self::error_at(
                    &at,
                    "environment variables are not supported",
                ))
            }
        }
        Ok(())
    }

    /// `VAL_ id signal value "text" ... ;`
    fn value_descriptions(&mut self) -> Result<(), ParseError> {
        let at = self.peek().cloned().expect("VAL_ was read");
        let (id, _) = self.message_id()?;
        let (signal, _) = self.ident("signal name")?;
        let entries = self.value_pairs()?;
        self.signal_mut(id, &signal, &at)?.value_descriptions = entries;
        Ok(())
    }
}

enum ObjectRef {
    Network,
    Node(String),
    Message(u32),
    Signal(u32, String),
    EnvironmentVariable,
}

fn parse_int(s: &str) -> Option<i64> {
    s.parse::<i64>().ok()
}

fn check_attribute_value(def: &AttributeDefinition, value: &AttributeValue) -> Result<(), String> {
    let name = &def.name;
    match (&def.kind, value) {
        (
            AttributeKind::Int { min, max } | AttributeKind::Hex { min, max },
            AttributeValue::Int(v),
        ) => {
            if v < min || v > max {
                return Err(format!(
                    "attribute \"{name}\" value {v} outside {min}..={max}"
                ));
            }
        }
        (AttributeKind::Float { min, max }, AttributeValue::Int(v)) => {
            let v = *v as f64;
            if v < *min || v > *max {
                return Err(format!(
                    "attribute \"{name}\" value {v} outside {min}..={max}"
                ));
            }
        }
        (AttributeKind::Float { min, max }, AttributeValue::Float(v)) => {
            if v < min || v > max {
                return Err(format!(
                    "attribute \"{name}\" value {v} outside {min}..={max}"
                ));
            }
        }
        (AttributeKind::String, AttributeValue::Str(_)) => {}
        (AttributeKind::Enum(values), AttributeValue::Int(i)) => {
            if *i < 0 || *i as usize >= values.len() {
                return Err(format!("attribute \"{name}\" enum index {i} out of range"));
            }
        }
        (AttributeKind::Enum(values), AttributeValue::Str(s)) => {
            if !values.contains(s) {
                return Err(format!("attribute \"{name}\" has no enum value \"{s}\""));
            }
        }
        (kind, value) => {
            return Err(format!(
                "attribute \"{name}\" is {kind:?}, but the value is {value:?}"
            ))
        }
    }
    Ok(())
}
