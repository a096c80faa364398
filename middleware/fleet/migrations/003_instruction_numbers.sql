-- Every instruction the fleet signs for a vehicle carries the next number of that
-- vehicle's series (Uptane's answer to replay): the vehicle keeps the highest it has
-- taken, across restarts, and refuses anything not newer.
CREATE TABLE instruction_numbers (
    vin TEXT PRIMARY KEY,
    issued BIGINT NOT NULL
);
