#!/bin/sh
# Bounds the I2C engine's handlers on both chips (README.md). Run from the repository's root after
# `cargo build -p xtask`.
set -e
cd tools/engine-bound
cargo build -q --release --target thumbv7m-none-eabi --features f1 --target-dir target/f1
cargo build -q --release --target thumbv7em-none-eabihf --features f4 --target-dir target/f4
cd ../..
for f in i2c_event i2c_error i2c_rearm engine_event engine_error 'amiro_firmware::i2c_bus::I2cBus<B,_>::settle' 'amiro_firmware::i2c_bus::Inner<B,_>::end' 'amiro_firmware::i2c_bus::wake' 'amiro_firmware::i2c_bus::I2cBus<B,_>::after_start' 'amiro_firmware::i2c_bus::I2cBus<B,_>::after_end'; do
  ./target/debug/xtask wcet --elf tools/engine-bound/target/f1/thumbv7m-none-eabi/release/engine-bound \
    --function "$f" --chip stm32f103 --bounds tools/engine-bound/bounds-f1.json
  ./target/debug/xtask wcet --elf tools/engine-bound/target/f4/thumbv7em-none-eabihf/release/engine-bound \
    --function "$f" --chip stm32f405 --bounds tools/engine-bound/bounds-f4.json
done
