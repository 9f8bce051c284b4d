#!/bin/sh
# Prints the code size of the DiWheelDrive I2C groups' scripted samples on the F103 (src/lib.rs)
# and whether any of it can reach a panic. Run from the repository's root; needs llvm-ar, llvm-size
# and llvm-nm.
set -e
cd tools/scripted-size
cargo build -q --release --target thumbv7m-none-eabi
lib=target/thumbv7m-none-eabi/release/libscripted_size.a
dir=target/objects
rm -rf "$dir" && mkdir -p "$dir"
member=$(llvm-ar t "$lib" | grep '^scripted_size')
(cd "$dir" && llvm-ar x "../../$lib" "$member")
llvm-size "$dir/$member"
llvm-nm --print-size --size-sort --radix=d "$dir/$member" | grep -E ' [Tt] ' | tail -8
if llvm-nm "$dir/$member" | grep -q panicking; then
  echo "a panic path is reachable"
else
  echo "no panic path"
fi
