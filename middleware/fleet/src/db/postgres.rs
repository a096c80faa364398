//! The fleet database on a PostgreSQL server: the engine for a fleet, shared by every fleet
//! service in front of it (they keep no state of their own).

use std::collections::HashMap;
use std::error::Error;
use std::str::FromStr;
use std::time::Duration;

use bytes::BytesMut;
use postgres::types::{to_sql_checked, IsNull, ToSql, Type};
use postgres::{Client, Config, NoTls, Statement};

use super::sqlite::first_line;
use super::{Db, DbError, Dialect, Row, Value};

/// How long connecting may take before it is an error.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// Statements kept prepared per connection, by text (the store has a few dozen; a query
/// built from a recall's filters is one of a few shapes).
const STATEMENT_CACHE: usize = 256;

/// A connection to a PostgreSQL database. A connection that dies (the server restarted
/// or failed over, an administrator or an idle timeout ended it) is made again at the next
/// statement outside a transaction; inside one the statement fails, and with it the
/// transaction, which its caller runs again from the start.
pub struct PostgresDb {
    client: Client,
    config: Config,
    name: String,
    statements: HashMap<String, Statement>,
    /// Transactions open on this connection, the outer one and the savepoints inside it
    /// (no reconnecting under one: its work would be lost, and a COMMIT on a new
    /// connection succeeds with nothing to commit).
    depth: usize,
}

impl PostgresDb {
    /// Connects to `url` (`postgresql://user@host:port/database`, or libpq's `key=value`
    /// form, including `options=-csearch_path=...` for a schema of its own).
    pub fn connect(url: &str) -> Result<Self, DbError> {
        let fail = |name: &str, message: String| DbError {
            database: name.to_string(),
            message,
        };
        let mut config = Config::from_str(url).map_err(|e| {
            fail(
                "PostgreSQL",
                format!("'{}' is not a PostgreSQL address: {e}", redact(url)),
            )
        })?;
        config
            .connect_timeout(CONNECT_TIMEOUT)
            .application_name("autoplug-fleet");
        let name = describe(&config);
        let client = config
            .connect(NoTls)
            .map_err(|e| fail(&name, format!("cannot connect: {}", full_error(&e))))?;
        Ok(Self {
            client,
            config,
            name,
            statements: HashMap::new(),
            depth: 0,
        })
    }

    /// Makes the connection again if it was lost and no transaction is open on it.
    fn live(&mut self) -> Result<(), DbError> {
        if !self.client.is_closed() || self.depth > 0 {
            return Ok(());
        }
        self.client = self.config.connect(NoTls).map_err(|e| DbError {
            database: self.name.clone(),
            message: format!(
                "the connection was lost and cannot be made again: {}",
                full_error(&e)
            ),
        })?;
        // Prepared statements belonged to the old connection.
        self.statements.clear();
        Ok(())
    }

    fn fail(&self, sql: &str, e: &postgres::Error) -> DbError {
        DbError {
            database: self.name.clone(),
            message: format!("{} (in: {})", full_error(e), first_line(sql)),
        }
    }

    fn statement(&mut self, sql: &str) -> Result<Statement, DbError> {
        if let Some(statement) = self.statements.get(sql) {
            return Ok(statement.clone());
        }
        let statement = self.client.prepare(sql).map_err(|e| self.fail(sql, &e))?;
        if self.statements.len() >= STATEMENT_CACHE {
            self.statements.clear();
        }
        self.statements.insert(sql.to_string(), statement.clone());
        Ok(statement)
    }

    fn params(params: &[Value]) -> Vec<&(dyn ToSql + Sync)> {
        params.iter().map(|p| p as &(dyn ToSql + Sync)).collect()
    }
}

/// The server, port and database, without user or password.
fn describe(config: &Config) -> String {
    let host = match config.get_hosts().first() {
        Some(postgres::config::Host::Tcp(host)) => host.clone(),
        Some(postgres::config::Host::Unix(path)) => path.display().to_string(),
        None => "localhost".into(),
    };
    let port = config.get_ports().first().copied().unwrap_or(5432);
    let db = config.get_dbname().unwrap_or("(default database)");
    format!("postgresql://{host}:{port}/{db}")
}

/// An address with any password replaced (for an error message about the address).
fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(scheme), Some(at)) if at > scheme => {
            let credentials = &url[scheme + 3..at];
            match credentials.split_once(':') {
                Some((user, _)) => format!("{}{user}:***{}", &url[..scheme + 3], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url
            .split_whitespace()
            .map(|kv| {
                if kv.starts_with("password=") {
                    "password=***"
                } else {
                    kv
                }
            })
            .collect::<Vec<_>>()
            .join(" "),
    }
}

/// The error with its causes (the driver's top-level text alone is often just "db error").
fn full_error(e: &postgres::Error) -> String {
    if let Some(db) = e.as_db_error() {
        return format!("{} {}: {}", db.severity(), db.code().code(), db.message());
    }
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

impl ToSql for Value {
    fn to_sql(
        &self,
        ty: &Type,
        out: &mut BytesMut,
    ) -> Result<IsNull, Box<dyn Error + Sync + Send>> {
        // Each value goes out as the column's own type, so the store's plain integers
        // and floats fit INTEGER, BIGINT and DOUBLE PRECISION columns alike.
        match self {
            Value::Null => Ok(IsNull::Yes),
            Value::Int(v) => match *ty {
                Type::INT8 => v.to_sql(ty, out),
                Type::INT4 => i32::try_from(*v)?.to_sql(ty, out),
                Type::INT2 => i16::try_from(*v)?.to_sql(ty, out),
                Type::FLOAT8 => (*v as f64).to_sql(ty, out),
                Type::BOOL => (*v != 0).to_sql(ty, out),
                _ => Err(format!("an integer cannot go into a {ty} parameter").into()),
            },
            Value::Float(v) => match *ty {
                Type::FLOAT8 => v.to_sql(ty, out),
                Type::FLOAT4 => (*v as f32).to_sql(ty, out),
                _ => Err(format!("a number cannot go into a {ty} parameter").into()),
            },
            Value::Text(v) => v.as_str().to_sql(ty, out),
            Value::Bytes(v) => v.as_slice().to_sql(ty, out),
        }
    }

    fn accepts(_: &Type) -> bool {
        // Checked per value in `to_sql`, against the parameter's actual type.
        true
    }

    to_sql_checked!();
}

fn value_at(row: &postgres::Row, i: usize) -> Result<Value, postgres::Error> {
    let ty = row.columns()[i].type_().clone();
    Ok(match ty {
        Type::INT8 => row.try_get::<_, Option<i64>>(i)?.into(),
        Type::INT4 => row.try_get::<_, Option<i32>>(i)?.map(i64::from).into(),
        Type::INT2 => row.try_get::<_, Option<i16>>(i)?.map(i64::from).into(),
        Type::BOOL => row.try_get::<_, Option<bool>>(i)?.map(i64::from).into(),
        Type::FLOAT8 => row.try_get::<_, Option<f64>>(i)?.into(),
        Type::FLOAT4 => row.try_get::<_, Option<f32>>(i)?.map(f64::from).into(),
        Type::BYTEA => match row.try_get::<_, Option<Vec<u8>>>(i)? {
            Some(bytes) => Value::Bytes(bytes),
            None => Value::Null,
        },
        // TEXT, VARCHAR, NAME and the rest that read as text; a type that does not
        // (NUMERIC from a SUM) is the statement's mistake and errors here.
        _ => row.try_get::<_, Option<String>>(i)?.into(),
    })
}

impl Db for PostgresDb {
    fn dialect(&self) -> Dialect {
        Dialect::Postgres
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, DbError> {
        self.live()?;
        let statement = self.statement(sql)?;
        self.client
            .execute(&statement, &Self::params(params))
            .map_err(|e| self.fail(sql, &e))
    }

    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, DbError> {
        self.live()?;
        let statement = self.statement(sql)?;
        let rows = self
            .client
            .query(&statement, &Self::params(params))
            .map_err(|e| self.fail(sql, &e))?;
        rows.iter()
            .map(|row| (0..row.len()).map(|i| value_at(row, i)).collect())
            .collect::<Result<Vec<Row>, _>>()
            .map_err(|e| self.fail(sql, &e))
    }

    fn batch(&mut self, sql: &str) -> Result<(), DbError> {
        self.live()?;
        self.client
            .batch_execute(sql)
            .map_err(|e| self.fail(sql, &e))
    }

    fn begin(&mut self) -> Result<(), DbError> {
        let sql = super::begin_sql(self.depth, "BEGIN");
        self.batch(&sql)?;
        self.depth += 1;
        Ok(())
    }

    fn commit(&mut self) -> Result<(), DbError> {
        // Over whatever the outcome: a failed COMMIT ends the transaction too.
        self.depth = self.depth.saturating_sub(1);
        self.batch(&super::commit_sql(self.depth))
    }

    fn rollback(&mut self) -> Result<(), DbError> {
        self.depth = self.depth.saturating_sub(1);
        self.batch(&super::rollback_sql(self.depth))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passwords_never_reach_a_message() {
        assert_eq!(
            redact("postgresql://fleet:s3cret@db.example:5432/fleet"),
            "postgresql://fleet:***@db.example:5432/fleet"
        );
        assert_eq!(
            redact("host=db user=fleet password=s3cret dbname=fleet"),
            "host=db user=fleet password=*** dbname=fleet"
        );
        assert_eq!(
            redact("postgresql://postgres@127.0.0.1/test"),
            "postgresql://postgres@127.0.0.1/test"
        );
    }
}
