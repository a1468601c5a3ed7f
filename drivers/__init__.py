"""Device drivers: transports, protocol codecs (plug-ins found by name), stream framers, sessions.

Modules, one job each:
``crc`` catalogue CRCs · ``codec`` the codec interface, frame-batch and raw-chunk records ·
``framing`` byte-stream framer and counter unwrapping · ``kvh1750``, ``xsens``, ``stim300``, ``tts1``,
``can_dbc``, ``acl`` the protocols · ``registry`` codec instances by name (the classes: ``hil.plugins``) ·
``tap`` raw and sample listeners ·
``transport`` pyserial and python-can transports · ``pty_guard`` no reopen onto another program's pty ·
``reader`` reader threads that survive replugs ·
``table_client`` turntable commands within limits · ``capture`` decoding of raw captures to CSV.
"""
