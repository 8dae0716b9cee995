"""The live view's engine hosts: in the UI process (`local`, threads) or in a child process (`remote`, frames
back through shared memory, `frame_ring`)."""
