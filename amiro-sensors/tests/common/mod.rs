//! Helpers the sensor tests share: the mock-transaction scripts of the ST parts' SPI transfers.

use embedded_hal_mock::eh1::spi::Transaction as T;

/// One `SpiDevice` transaction that sends a command byte, then reads `response`.
pub fn read_tx(command: u8, response: &[u8]) -> Vec<T<u8>> {
    vec![
        T::transaction_start(),
        T::write_vec(vec![command]),
        T::read_vec(response.to_vec()),
        T::transaction_end(),
    ]
}

/// One `SpiDevice` transaction that sends a command byte, then writes `data`.
#[allow(dead_code)] // not every test file writes
pub fn write_tx(command: u8, data: &[u8]) -> Vec<T<u8>> {
    vec![
        T::transaction_start(),
        T::write_vec(vec![command]),
        T::write_vec(data.to_vec()),
        T::transaction_end(),
    ]
}
