//! The contents of a DBC file, as plain data.

/// A whole CAN database.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Database {
    /// The `VERSION` string.
    pub version: String,
    /// `BU_`: the nodes on the bus.
    pub nodes: Vec<Node>,
    /// `VAL_TABLE_`: named value tables.
    pub value_tables: Vec<ValueTable>,
    /// `BO_`: the messages.
    pub messages: Vec<Message>,
    /// `CM_ "..."`: the comment on the network itself.
    pub comment: Option<String>,
    /// `BA_DEF_` with their `BA_DEF_DEF_` defaults.
    pub attribute_definitions: Vec<AttributeDefinition>,
    /// `BA_` on the network.
    pub attributes: Vec<(String, AttributeValue)>,
}

/// A node (ECU) on the bus.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Node {
    /// Its name in `BU_`.
    pub name: String,
    /// `CM_ BU_`.
    pub comment: Option<String>,
    /// `BA_ ... BU_`.
    pub attributes: Vec<(String, AttributeValue)>,
}

/// A named table of raw values and their meanings.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ValueTable {
    /// Table name.
    pub name: String,
    /// Raw value and description, in file order.
    pub entries: Vec<(i64, String)>,
}

/// A CAN frame layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Message {
    /// Identifier without the DBC's extended-frame flag (bit 31).
    pub id: u32,
    /// Whether the DBC marked the identifier as 29-bit.
    pub extended: bool,
    /// Name.
    pub name: String,
    /// Data length in bytes.
    pub dlc: u8,
    /// Sending nodes: the `BO_` transmitter first, then those of `BO_TX_BU_`.
    pub transmitters: Vec<String>,
    /// Signals in file order.
    pub signals: Vec<Signal>,
    /// `CM_ BO_`.
    pub comment: Option<String>,
    /// `BA_ ... BO_`.
    pub attributes: Vec<(String, AttributeValue)>,
    /// Line of the `BO_` statement, for messages about it.
    pub line: usize,
}

/// Bit numbering of a signal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ByteOrder {
    /// `@1`: Intel, least significant byte first.
    #[default]
    LittleEndian,
    /// `@0`: Motorola, most significant byte first.
    BigEndian,
}

/// Multiplexing role of a signal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Multiplexing {
    /// An ordinary signal.
    #[default]
    None,
    /// `M`: the multiplexer switch.
    Multiplexer,
    /// `mN`: present when the switch reads N.
    Multiplexed(u32),
}

/// A value inside a message.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Signal {
    /// Name, unique within its message.
    pub name: String,
    /// Start bit as written in the DBC.
    pub start_bit: u16,
    /// Length in bits.
    pub length: u16,
    /// Bit numbering.
    pub byte_order: ByteOrder,
    /// Two's complement raw value.
    pub signed: bool,
    /// physical = raw * factor + offset.
    pub factor: f64,
    /// See `factor`.
    pub offset: f64,
    /// Smallest valid physical value (`[min|max]`; `[0|0]` means "whole raw range").
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Unit text.
    pub unit: String,
    /// Receiving nodes (`Vector__XXX`, meaning none, is dropped).
    pub receivers: Vec<String>,
    /// Multiplexing role.
    pub multiplexing: Multiplexing,
    /// `CM_ SG_`.
    pub comment: Option<String>,
    /// `VAL_`: raw value and description, in file order.
    pub value_descriptions: Vec<(i64, String)>,
    /// `BA_ ... SG_`.
    pub attributes: Vec<(String, AttributeValue)>,
    /// Line of the `SG_` statement.
    pub line: usize,
}

/// Which kind of object an attribute belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttributeObject {
    /// The network (no object keyword).
    Network,
    /// `BU_`.
    Node,
    /// `BO_`.
    Message,
    /// `SG_`.
    Signal,
    /// `EV_`.
    EnvironmentVariable,
}

/// The value type of an attribute.
#[derive(Clone, Debug, PartialEq)]
pub enum AttributeKind {
    /// `INT min max`.
    Int {
        /// Smallest value.
        min: i64,
        /// Largest value.
        max: i64,
    },
    /// `HEX min max`.
    Hex {
        /// Smallest value.
        min: i64,
        /// Largest value.
        max: i64,
    },
    /// `FLOAT min max`.
    Float {
        /// Smallest value.
        min: f64,
        /// Largest value.
        max: f64,
    },
    /// `STRING`.
    String,
    /// `ENUM "a","b"`: values are indices into the list.
    Enum(Vec<String>),
}

/// `BA_DEF_` and its `BA_DEF_DEF_`.
#[derive(Clone, Debug, PartialEq)]
pub struct AttributeDefinition {
    /// Object kind it applies to.
    pub object: AttributeObject,
    /// Name.
    pub name: String,
    /// Value type.
    pub kind: AttributeKind,
    /// Default value, if `BA_DEF_DEF_` gives one.
    pub default: Option<AttributeValue>,
}

/// An attribute value.
#[derive(Clone, Debug, PartialEq)]
pub enum AttributeValue {
    /// Integer (INT, HEX and ENUM index).
    Int(i64),
    /// FLOAT.
    Float(f64),
    /// STRING (or an ENUM given by name).
    Str(String),
}

impl AttributeValue {
    /// The value as an integer, if it is one.
    pub fn as_int(&self) -> Option<i64> {
        match self {
            AttributeValue::Int(v) => Some(*v),
            AttributeValue::Float(v) if v.fract() == 0.0 => Some(*v as i64),
            _ => None,
        }
    }
}

fn find<'a>(list: &'a [(String, AttributeValue)], name: &str) -> Option<&'a AttributeValue> {
    list.iter().find(|(n, _)| n == name).map(|(_, v)| v)
}

impl Database {
    /// The message with this name.
    pub fn message(&self, name: &str) -> Option<&Message> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The message with this identifier.
    pub fn message_by_id(&self, id: u32) -> Option<&Message> {
        self.messages.iter().find(|m| m.id == id)
    }

    /// The node with this name.
    pub fn node(&self, name: &str) -> Option<&Node> {
        self.nodes.iter().find(|n| n.name == name)
    }

    /// The definition of an attribute for an object kind.
    pub fn attribute_definition(
        &self,
        object: AttributeObject,
        name: &str,
    ) -> Option<&AttributeDefinition> {
        self.attribute_definitions
            .iter()
            .find(|d| d.object == object && d.name == name)
    }

    fn default_of(&self, object: AttributeObject, name: &str) -> Option<&AttributeValue> {
        self.attribute_definition(object, name)
            .and_then(|d| d.default.as_ref())
    }

    /// A network attribute, or its default.
    pub fn network_attribute(&self, name: &str) -> Option<&AttributeValue> {
        find(&self.attributes, name).or_else(|| self.default_of(AttributeObject::Network, name))
    }

    /// A node attribute, or its default.
    pub fn node_attribute<'a>(&'a self, node: &'a Node, name: &str) -> Option<&'a AttributeValue> {
        find(&node.attributes, name).or_else(|| self.default_of(AttributeObject::Node, name))
    }

    /// A message attribute, or its default.
    pub fn message_attribute<'a>(
        &'a self,
        message: &'a Message,
        name: &str,
    ) -> Option<&'a AttributeValue> {
        find(&message.attributes, name).or_else(|| self.default_of(AttributeObject::Message, name))
    }

    /// A signal attribute, or its default.
    pub fn signal_attribute<'a>(
        &'a self,
        signal: &'a Signal,
        name: &str,
    ) -> Option<&'a AttributeValue> {
        find(&signal.attributes, name).or_else(|| self.default_of(AttributeObject::Signal, name))
    }
}

impl Message {
    /// The signal with this name.
    pub fn signal(&self, name: &str) -> Option<&Signal> {
        self.signals.iter().find(|s| s.name == name)
    }
}

impl Signal {
    /// The raw range the signal's bits can hold.
    pub fn bit_range(&self) -> (i64, i64) {
        let len = u32::from(self.length.clamp(1, 64));
        if self.signed {
            if len == 64 {
                (i64::MIN, i64::MAX)
            } else {
                (-(1i64 << (len - 1)), (1i64 << (len - 1)) - 1)
            }
        } else if len >= 63 {
            (0, i64::MAX)
        } else {
            (0, (1i64 << len) - 1)
        }
    }

    /// The valid raw range: `[min|max]` converted to raw steps, or the whole bit range for
    /// `[0|0]`. A bound that falls within 1e-6 of a step counts as that step, so decimal
    /// factors such as 9000/255 do not lose their end points to rounding.
    pub fn raw_range(&self) -> (i64, i64) {
        let (bit_lo, bit_hi) = self.bit_range();
        if self.min == 0.0 && self.max == 0.0 {
            return (bit_lo, bit_hi);
        }
        let a = (self.min - self.offset) / self.factor;
        let b = (self.max - self.offset) / self.factor;
        let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
        let snap = |x: f64| {
            let r = x.round();
            if (x - r).abs() < 1e-6 {
                Some(r)
            } else {
                None
            }
        };
        let lo = snap(lo).unwrap_or_else(|| lo.ceil());
        let hi = snap(hi).unwrap_or_else(|| hi.floor());
        let lo = (lo.max(bit_lo as f64)) as i64;
        let hi = (hi.min(bit_hi as f64)) as i64;
        (lo.max(bit_lo), hi.min(bit_hi))
    }

    /// Bit positions (0 = bit 0 of byte 0, 8 = bit 0 of byte 1) the signal occupies,
    /// least significant first for Intel and most significant first for Motorola.
    pub fn bits(&self) -> Vec<u32> {
        let start = u32::from(self.start_bit);
        match self.byte_order {
            ByteOrder::LittleEndian => (start..start + u32::from(self.length)).collect(),
            ByteOrder::BigEndian => {
                // Motorola: the start bit is the MSB; walk towards the LSB across bytes.
                let mut bits = Vec::with_capacity(usize::from(self.length));
                let mut bit = start;
                for _ in 0..self.length {
                    bits.push(bit);
                    bit = if bit % 8 == 0 { bit + 15 } else { bit - 1 };
                }
                bits
            }
        }
    }
}
