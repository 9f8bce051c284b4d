#!/bin/sh
# Prints the code size of the DiWheelDrive I2C groups' scripted samples on the F103 (src/lib.rs),
# its largest stack frame and whether any of it can reach a panic. Run from the repository's root;
# needs llvm-ar, llvm-size, llvm-nm and llvm-objdump.
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
# The largest stack frame one function reserves (`sub sp, #n`; a call chain adds its callees').
llvm-objdump -d --no-show-raw-insn "$dir/$member" | awk '
  /^[0-9a-f]+ <.*>:$/ { f = $2 }
  /\tsub(\.w|w)?\tsp, (sp, )?#/ { match($0, /#[0-9]+/); v = substr($0, RSTART + 1, RLENGTH - 1) + 0; if (v > m) { m = v; g = f } }
  END { print "largest stack frame: " m " B in " g }'
if llvm-nm "$dir/$member" | grep -q panicking; then
  echo "a panic path is reachable"
else
  echo "no panic path"
fi
