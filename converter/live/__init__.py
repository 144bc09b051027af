"""`facesvg live`: what face-tracking apps stream, bridged to the puppet player's WebSocket feed.

`packets` turns one datagram (Live Link Face, iFacialMocap, VMC over OSC) into a `LiveFrame`; `server` listens for
them on UDP and broadcasts each frame as the player's JSON message to every connected player.
"""
