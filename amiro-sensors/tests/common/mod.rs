//! Helpers the sensor tests share: the mock-transaction scripts of the ST parts' SPI transfers.

use embedded_hal_mock::eh1::spi::Transaction as T;

/// One `SpiDevice` transaction that sends a command byte and dummy zeros, and reads `response`
/// during the zeros: one transfer in place of the whole frame (amiro-sensors' `st_spi`); what
/// the part shifts out during the command byte is not a register (0xFF here: a part that answers
/// nothing useful there must not be taken for one).
pub fn read_tx(command: u8, response: &[u8]) -> Vec<T<u8>> {
    let mut sent = vec![command];
    sent.extend(std::iter::repeat_n(0, response.len()));
    let mut answer = vec![0xFF];
    answer.extend_from_slice(response);
    vec![
        T::transaction_start(),
        T::transfer_in_place(sent, answer),
        T::transaction_end(),
    ]
}

/// One `SpiDevice` transaction that sends a command byte, then `data`: one transfer in place of
/// the whole frame, whose answer (0xFF here) the driver ignores.
#[allow(dead_code)] // not every test file writes
pub fn write_tx(command: u8, data: &[u8]) -> Vec<T<u8>> {
    let mut sent = vec![command];
    sent.extend_from_slice(data);
    vec![
        T::transaction_start(),
        T::transfer_in_place(sent.clone(), vec![0xFF; sent.len()]),
        T::transaction_end(),
    ]
}
