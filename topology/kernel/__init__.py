"""The kernel part: what the testbed asks of Linux inside its own namespaces.

Namespaces (netns), batched rtnetlink (rtnl, netlinkmsg), route look-ups (routequery), link
impairments with tc and nftables (impair), the emulated-time network timers (nettimers),
programs started in a namespace (processes, forkserver) and packet captures (capture)."""
